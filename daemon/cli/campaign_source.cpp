#include "daemon/cli/campaign_source.hpp"

#include <filesystem>

#include <fmt/core.h>

#include "analysis/input_error.hpp"
#include "daemon/core/database_export.hpp"
#include "daemon/core/recorder/database.hpp"
#include "daemon/core/user_error.hpp"

namespace manikind::cli {

void add_campaign_source_options(CLI::App* cmd, CampaignSource& source) {
    cmd->add_option("campaign", source.campaign,
                    "Campaign folder in the manikin-recording/1 format: campaign.json + trials/<id>.csv\n"
                    "(with --db: the campaign's name in the database)");
    cmd->add_option("--db", source.db,
                    "Read the campaign from the daemon's SQLite database instead of a folder (default campaign: the newest)");
    cmd->add_option("--campaign", source.campaign, "The campaign's name (same as the positional argument)");
}

analysis::Campaign read_campaign_source(const CampaignSource& source, const analysis::ReadOptions& options) {
    try {
        if (source.db.empty()) {
            if (source.campaign.empty()) throw UserError("give the campaign folder, or --db <file> [--campaign <name>]");
            return analysis::read_campaign(source.campaign, options);
        }
        if (!std::filesystem::exists(source.db)) throw UserError(fmt::format("{}: no such database", source.db));
        auto db = recorder::Database::open(source.db);
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
