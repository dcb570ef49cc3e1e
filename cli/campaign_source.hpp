#pragma once
// Where a command reads a recorded campaign from: a folder (manikin-recording/1), the daemon's
// database with --db FILE [--campaign NAME], or the PostgreSQL archive with --archive CONNINFO
// --lab ID --campaign NAME. One rule for every command that reads campaigns (analyze, reconcile;
// docs/cli.md).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "analysis/recording.hpp"
#include "store/database.hpp"

namespace manikind::cli {

struct CampaignSource {
    std::string campaign;  // the folder, or with --db/--archive the campaign's name (empty = the newest in --db)
    std::string db;        // the daemon's SQLite database; empty = read a folder (or the archive)
    std::string archive;   // a libpq conninfo of the archive (docs/archive.md); empty = not the archive
    std::string lab;       // with --archive: the lab id the campaign was pushed under
};

// The positional `campaign`, --db, --campaign (the same as the positional), --archive and --lab.
void add_campaign_source_options(CLI::App* cmd, CampaignSource& source);

// What a command reading `source` must never write over (store/export_target.hpp,
// refuse_protected_output): the campaign folder, or the database file; nothing local for the
// archive (its pull is a temporary file of this process).
std::vector<std::filesystem::path> source_inputs(const CampaignSource& source);

// Reads the campaign; input problems (no such folder or database, unknown campaign or lab) are
// UserError, an unreachable archive too (status 3).
analysis::Campaign read_campaign_source(const CampaignSource& source, const analysis::ReadOptions& options = {});

// One lab's campaign from the archive: pulled into a temporary SQLite file (removed before this
// returns or throws) and read by campaign_from_database, as a lab's own file would be.
analysis::Campaign campaign_from_archive(const std::string& conninfo, const std::string& lab_id,
                                         const std::string& campaign_name);

// The same pull, kept open for a reader that goes a trial at a time (`manikin export`: memory
// flat in the campaign's length, as from a lab's own file). The file and its folder go with it.
class PulledCampaign {
public:
    PulledCampaign(const std::string& conninfo, const std::string& lab_id, const std::string& campaign_name);
    ~PulledCampaign();
    PulledCampaign(const PulledCampaign&) = delete;
    PulledCampaign& operator=(const PulledCampaign&) = delete;
    recorder::Database& database() { return *db_; }
    // Where the numbers came from, for the campaign's provenance (no password: conninfo may hold one).
    const std::string& source() const { return source_; }

private:
    std::filesystem::path folder_;
    std::optional<recorder::Database> db_;
    std::string source_;
};

}  // namespace manikind::cli
