#include "cli/campaign_source.hpp"

#include <stdlib.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include <fmt/core.h>

#include "analysis/input_error.hpp"
#include "archive/pull.hpp"
#include "store/database_export.hpp"
#include "store/database.hpp"
#include "base/user_error.hpp"

namespace manikind::cli {
namespace {

// A new folder under $TMPDIR (or /tmp) that only this user can enter (mkdtemp).
std::filesystem::path make_private_folder() {
    const char* tmpdir = std::getenv("TMPDIR");
    std::string pattern = std::string(tmpdir && *tmpdir ? tmpdir : "/tmp") + "/manikin-archive-XXXXXX";
    if (!mkdtemp(pattern.data()))
        throw UserError(fmt::format("cannot create a temporary folder {}: {}", pattern, std::strerror(errno)));
    return pattern;
}

}  // namespace

void add_campaign_source_options(CLI::App* cmd, CampaignSource& source) {
    cmd->add_option("campaign", source.campaign,
                    "Campaign folder in the manikin-recording/1 format: campaign.json + trials/<id>.csv\n"
                    "(with --db or --archive: the campaign's name)");
    auto* db = cmd->add_option("--db", source.db,
                               "Read the campaign from the daemon's SQLite database instead of a folder "
                               "(default campaign: the newest)");
    cmd->add_option("--campaign", source.campaign, "The campaign's name (same as the positional argument)");
    auto* archive = cmd->add_option("--archive", source.archive,
                                    "Read the campaign from the PostgreSQL archive (a libpq conninfo or URI, "
                                    "docs/archive.md); needs --lab and the campaign's name");
    auto* lab = cmd->add_option("--lab", source.lab, "With --archive: the lab id the campaign was pushed under");
    archive->excludes(db);
    lab->needs(archive);
}

analysis::Campaign campaign_from_archive(const std::string& conninfo, const std::string& lab_id,
                                         const std::string& campaign_name) {
    PulledCampaign pulled(conninfo, lab_id, campaign_name);  // its file and folder go when this returns
    analysis::Campaign c = campaign_from_database(pulled.database(), campaign_name);
    c.provenance["database"] = pulled.source();  // not the temporary file's name
    return c;
}

PulledCampaign::PulledCampaign(const std::string& conninfo, const std::string& lab_id, const std::string& campaign_name)
    : folder_(make_private_folder()) {
    try {
        db_.emplace(recorder::Database::open(folder_ / "pulled.db"));
        const auto pulled = archive::pull_campaign(conninfo, lab_id, campaign_name, *db_);
        source_ = fmt::format("archive {} lab {}", pulled.archive, lab_id);
    } catch (...) {
        db_.reset();  // closed before its folder goes
        std::error_code ec;
        std::filesystem::remove_all(folder_, ec);
        throw;
    }
}

PulledCampaign::~PulledCampaign() {
    db_.reset();
    std::error_code ec;
    std::filesystem::remove_all(folder_, ec);
}

std::vector<std::filesystem::path> source_inputs(const CampaignSource& source) {
    if (!source.archive.empty()) return {};
    if (!source.db.empty()) return {source.db};
    if (!source.campaign.empty()) return {source.campaign};
    return {};
}

analysis::Campaign read_campaign_source(const CampaignSource& source, const analysis::ReadOptions& options) {
    try {
        if (!source.archive.empty()) {
            if (source.lab.empty())
                throw UserError("--archive needs --lab <id>: the lab the campaign was pushed under");
            if (source.campaign.empty()) throw UserError("--archive needs the campaign's name (--campaign <name>)");
            return campaign_from_archive(source.archive, source.lab, source.campaign);
        }
        if (source.db.empty()) {
            if (source.campaign.empty())
                throw UserError("give the campaign folder, or --db <file> [--campaign <name>], or --archive <conninfo> "
                                "--lab <id> --campaign <name>");
            return analysis::read_campaign(source.campaign, options);
        }
        auto db = recorder::Database::open_read_only(source.db);
        std::string name = source.campaign;
        if (name.empty()) {
            const auto campaigns = db.campaigns();  // by id: the last one is the newest
            if (campaigns.empty()) throw UserError(fmt::format("{}: the database holds no campaign", source.db));
            name = campaigns.back().name;
        }
        return campaign_from_database(db, name);
    } catch (const analysis::InputError& e) {
        throw UserError(e.what());
    }
}

}  // namespace manikind::cli
