#pragma once
// Where a command reads a recorded campaign from: a folder (manikin-recording/1), or the daemon's
// database with --db FILE [--campaign NAME]. One rule for every command that reads campaigns
// (analyze, reconcile; docs/cli.md).
#include <string>

#include <CLI/CLI.hpp>

#include "analysis/recording.hpp"

namespace manikind::cli {

struct CampaignSource {
    std::string campaign;  // the folder, or with --db the campaign's name (empty = the newest)
    std::string db;        // the daemon's SQLite database; empty = read a folder
};

// The positional `campaign`, --db and --campaign (the same as the positional).
void add_campaign_source_options(CLI::App* cmd, CampaignSource& source);

// Reads the campaign; input problems (no such folder or database, unknown campaign) are UserError.
analysis::Campaign read_campaign_source(const CampaignSource& source, const analysis::ReadOptions& options = {});

}  // namespace manikind::cli
