// `manikin archive push`: store and forward a daemon's SQLite file into the lab-wide PostgreSQL
// archive (issue 19, docs/archive.md). Run it as often as wanted: it sends what is new and
// resumes a push that was cut off.
#include <cstdio>
#include <memory>
#include <string>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "analysis/interlab_report.hpp"
#include "archive/forwarder.hpp"
#include "archive/pg.hpp"
#include "cli/campaign_source.hpp"
#include "cli/commands.hpp"
#include "daemon/config.hpp"
#include "base/user_error.hpp"

namespace manikind::cli {
namespace {

struct PushArgs {
    std::string db;
    std::string conninfo;
    std::string lab;
    std::string lab_name;
    std::size_t chunk_rows = 50'000;
    bool json = false;
};

nlohmann::json to_json(const archive::TableCounts& c) { return {{"sent", c.sent}, {"added", c.added}}; }

void run_push(const PushArgs& a) {
    archive::PushOptions options;
    options.chunk_rows = a.chunk_rows;
    options.lab_name = a.lab_name;
    if (!a.json) {
        options.after_chunk = [](const archive::ChunkCommitted& c) {
            std::fprintf(stderr, "trial %s: %lld samples committed (%lld new)\n", c.trial_uuid.c_str(),
                         static_cast<long long>(c.rows), static_cast<long long>(c.added));
        };
    }
    const auto r = archive::push(a.db, a.conninfo, a.lab, options);
    if (a.json) {
        const nlohmann::json doc = {{"archive", r.archive},
                                    {"lab", r.lab_id},
                                    {"database", a.db},
                                    {"archive_schema_version", r.archive_schema_version},
                                    {"campaigns", to_json(r.campaigns)},
                                    {"trials", to_json(r.trials)},
                                    {"channels", to_json(r.channels)},
                                    {"events", to_json(r.events)},
                                    {"samples", to_json(r.samples)},
                                    {"devices", to_json(r.devices)},
                                    {"results", to_json(r.results)},
                                    {"twin_versions", to_json(r.twin_versions)},
                                    {"idle_samples", to_json(r.idle_samples)},
                                    {"setups", to_json(r.setups)},
                                    {"notes", to_json(r.notes)},
                                    {"chunks", r.chunks},
                                    {"chunks_resent", r.chunks_resent},
                                    {"idle_chunks", r.idle_chunks},
                                    {"idle_resent", r.idle_resent},
                                    {"trials_complete", r.trials_complete},
                                    {"trials_partial", r.trials_partial}};
        std::printf("%s\n", doc.dump(2).c_str());
        return;
    }
    std::printf("pushed %s as lab %s to %s (archive schema v%d)\n", a.db.c_str(), r.lab_id.c_str(), r.archive.c_str(),
                r.archive_schema_version);
    std::printf("%-13s %12s %12s\n", "table", "sent", "new/changed");
    const auto row = [](const char* name, const archive::TableCounts& c) {
        std::printf("%-13s %12lld %12lld\n", name, static_cast<long long>(c.sent), static_cast<long long>(c.added));
    };
    row("campaigns", r.campaigns);
    row("trials", r.trials);
    row("channels", r.channels);
    row("events", r.events);
    row("samples", r.samples);
    row("devices", r.devices);
    row("results", r.results);
    row("twin_versions", r.twin_versions);
    row("idle_samples", r.idle_samples);
    row("setups", r.setups);
    row("notes", r.notes);
    if (r.chunks_resent)
        std::printf("samples: %lld chunks met rows the archive already had though no progress said so: sent again, none doubled\n",
                    static_cast<long long>(r.chunks_resent));
    if (r.idle_resent) std::printf("idle log: rows appeared behind what was sent (clock stepped back?): resent all\n");
    std::printf("trials with every sample archived: %lld; still running, sent so far: %lld\n",
                static_cast<long long>(r.trials_complete), static_cast<long long>(r.trials_partial));
}

struct CompareArgs {
    std::string conninfo;
    std::string campaign;
    std::vector<std::string> labs;
    bool json = false;
};

// Every lab's copy of the campaign, pulled and analysed as `analyze --archive` does, then ISO
// 5725-2 across the labs case by case.
void run_compare(const CompareArgs& a) {
    std::vector<std::string> labs = a.labs;
    if (labs.empty()) {
        auto pg = archive::PgConnection::connect(a.conninfo);
        auto r = pg.exec("SELECT lab_id FROM campaigns WHERE campaign_name = $1 ORDER BY lab_id", {a.campaign});
        for (int i = 0; i < r.rows(); ++i) labs.push_back(r.text(i, 0));
        if (labs.empty())
            throw UserError(fmt::format("archive {}: no lab holds a campaign named '{}'", pg.describe(), a.campaign));
    }
    const config::Config cfg = config::default_config();
    analysis::AnalysisOptions options;
    options.steady.window_s = cfg.steady_state.window_s;
    options.steady.max_skin_fluctuation_c = cfg.steady_state.max_skin_fluctuation_c;
    std::vector<analysis::LabCampaignResult> results;
    for (const auto& lab : labs) {
        if (!a.json) std::fprintf(stderr, "lab %s: pulling and analysing '%s'\n", lab.c_str(), a.campaign.c_str());
        results.push_back({lab, analysis::analyze_campaign(campaign_from_archive(a.conninfo, lab, a.campaign), options)});
    }
    const auto report = analysis::compare_labs(a.campaign, results);
    // What each lab measured with: its chamber, manikin and calibration set-ups for this campaign
    // (archive schema v3; an archive no push of this version has reached has none).
    nlohmann::json setups = nlohmann::json::object();
    {
        auto pg = archive::PgConnection::connect(a.conninfo);
        const bool have = pg.exec("SELECT to_regclass('trial_setups') IS NOT NULL").text(0, 0) == "t";
        for (const auto& lab : labs) {
            setups[lab] = nlohmann::json::array();
            if (!have) continue;
            auto r = pg.exec("SELECT setup_sha256, chamber, manikin, count(*) FROM trial_setups"
                             " WHERE lab_id = $1 AND campaign_name = $2 AND setup_sha256 IS NOT NULL"
                             " GROUP BY setup_sha256, chamber, manikin ORDER BY min(trial_uuid)",
                             {lab, a.campaign});
            for (int i = 0; i < r.rows(); ++i)
                setups[lab].push_back({{"setup_sha256", r.text(i, 0)},
                                       {"chamber", r.text(i, 1)},
                                       {"manikin", r.text(i, 2)},
                                       {"trials", std::stoll(r.text(i, 3))}});
        }
    }
    if (a.json) {
        auto doc = analysis::interlab_to_json(report);
        doc["setups"] = setups;
        std::printf("%s\n", doc.dump(2).c_str());
        return;
    }
    std::printf("%s", analysis::interlab_to_text(report).c_str());
    std::printf("\nSet-ups (chamber, manikin; calibration and configuration in the archive's trial_setups view):\n");
    for (const auto& lab : labs) {
        if (setups[lab].empty()) std::printf("  %s: none recorded (pushed before recorder schema v7)\n", lab.c_str());
        for (const auto& su : setups[lab])
            std::printf("  %s: %s; %s (%lld trials, set-up %s)\n", lab.c_str(),
                        su["chamber"].get<std::string>().empty() ? "chamber not named" : su["chamber"].get<std::string>().c_str(),
                        su["manikin"].get<std::string>().empty() ? "manikin not named" : su["manikin"].get<std::string>().c_str(),
                        static_cast<long long>(su["trials"].get<std::int64_t>()),
                        su["setup_sha256"].get<std::string>().substr(0, 12).c_str());
    }
}

}  // namespace

void add_archive_command(CLI::App& app) {
    auto* cmd = app.add_subcommand("archive", "Lab-wide PostgreSQL archive: store and forward (docs/archive.md)");
    cmd->require_subcommand(1);
    auto args = std::make_shared<PushArgs>();
    auto* push = cmd->add_subcommand("push", "Send a daemon database's campaigns, trials, devices, channels, events, "
                                             "samples, idle log, results, twin versions and set-ups to the archive; sends "
                                             "only what is new, resumes an interrupted push");
    push->add_option("db", args->db, "The daemon's SQLite database (read only; the daemon may be running)")->required();
    push->add_option("--to", args->conninfo, "libpq connection string, e.g. \"host=archive dbname=manikin user=lab3\"")
        ->required();
    push->add_option("--lab", args->lab, "This lab's id in the archive (letters, digits, - _ .)")->required();
    push->add_option("--lab-name", args->lab_name, "Name stored for a lab the archive has not seen (default: the id)");
    push->add_option("--chunk-rows", args->chunk_rows, "Samples per transaction")
        ->check(CLI::Range(std::size_t{1}, std::size_t{10'000'000}));
    push->add_flag("--json", args->json, "Print the counts as JSON");
    push->footer("Exit status 0 when everything was sent, 2 for a missing or foreign database or a bad --lab or --to,\n"
                 "3 when the server cannot be reached or the connection drops (run again: it resumes), 4 when the\n"
                 "server refuses (permissions, a trial another lab owns, another push of this lab running).");
    push->callback([args] { run_push(*args); });

    auto cmp = std::make_shared<CompareArgs>();
    auto* compare = cmd->add_subcommand(
        "compare", "One campaign measured in several labs: each lab's whole-body flux with its 95 % CI per case, and "
                   "ISO 5725-2 repeatability and reproducibility SDs across the labs");
    compare->add_option("--archive", cmp->conninfo, "libpq connection string of the archive")->required();
    compare->add_option("--campaign", cmp->campaign, "The campaign's name, the same in every lab")->required();
    compare->add_option("--lab", cmp->labs, "A lab to compare (repeatable; default: every lab holding the campaign)");
    compare->add_flag("--json", cmp->json, "Print the report as JSON");
    compare->footer("Example: manikin archive compare --archive \"host=archive.lab dbname=manikin\" --campaign round-robin-2026\n"
                    "Cases are matched by id; a case needs two labs with two usable replicates each. Then, per case:\n"
                    "s_r (within labs), s_L (between labs), s_R = sqrt(s_r^2 + s_L^2), r = 2.8 s_r, R = 2.8 s_R,\n"
                    "Mandel's h and k per lab and Cochran's C (ISO 5725-2 7.3-7.4). Per lab, reconcile finds what\n"
                    "sets one lab apart: manikin reconcile --archive ... --lab <id> --campaign <name>.\n"
                    "Exit status 2 for an unknown campaign or lab, 3 when the archive cannot be reached.");
    compare->callback([cmp] { run_compare(*cmp); });
}

}  // namespace manikind::cli
