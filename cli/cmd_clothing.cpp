// `manikin clothing <campaign>`: a garment's thermal insulation and evaporative resistance from a
// standard clothing test (ASTM F1291, ISO 15831, ASTM F2370; analysis/clothing.hpp), with 95 %
// intervals, the replicate criterion and a one-page report per ensemble.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "analysis/analyze.hpp"
#include "analysis/clothing.hpp"
#include "base/user_error.hpp"
#include "cli/campaign_source.hpp"
#include "cli/commands.hpp"
#include "store/export_target.hpp"

namespace manikind::cli {

void add_clothing_command(CLI::App& app) {
    struct Opts {
        CampaignSource source;
        std::string baseline, report, redress_from;
        bool json = false, force = false;
        bool require_flux_stability = false;
        bool skin_steadiness_only = false;
        analysis::clothing::Options options;
        // The replicate criteria in percent, as every output prints them (5 means 5 %).
        double cv_limit_insulation_pct = 5.0, cv_limit_evaporative_pct = 10.0;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("clothing", "Clothing insulation (It, Icle, Icl) and evaporative resistance (Ret, Recl, "
                                               "im) from a standard manikin test, with 95 % intervals");
    add_campaign_source_options(cmd, o->source);
    cmd->add_option("--baseline", o->baseline,
                    "A campaign with the nude manikin's trials (ensemble \"nude\"), when this one has none: a folder, or "
                    "with --db a campaign in the same database");
    cmd->add_option("--redress-from", o->redress_from,
                    "An earlier test of this lab with replicates (a folder, or with --db a campaign there): where an "
                    "ensemble has one replicate, its Type A is the re-dressing scatter pooled from that test's ensembles "
                    "(without it a 1-replicate interval excludes re-dressing and says so)");
    cmd->add_flag("--json", o->json, "Print one JSON document (docs/formats.md section 5) instead of the table");
    cmd->add_option("--report", o->report, "Write the one-page-per-ensemble report (HTML with SVG) to this file (new; "
                                           "never inside a campaign folder it reads, never over a database)");
    cmd->add_flag("--force", o->force, "Replace an existing report file");
    cmd->add_option("--cv-limit-insulation", o->cv_limit_insulation_pct,
                    "Largest coefficient of variation of the re-dressed replicates' total insulation, in % (5 = 5 %)")
        ->check(CLI::Range(0.1, 100.0))
        ->capture_default_str();
    cmd->add_option("--cv-limit-evaporative", o->cv_limit_evaporative_pct,
                    "Largest coefficient of variation of the replicates' total evaporative resistance, in % (10 = 10 %)")
        ->check(CLI::Range(0.1, 100.0))
        ->capture_default_str();
    cmd->add_flag("--skin-steadiness-only", o->skin_steadiness_only,
                  "Judge steady state by skin temperature alone (the paper's rule). By default a trial is also steady in "
                  "heat loss as the clothing standards ask: the whole-body heat loss moves at most 3 % and the mean skin "
                  "temperature 0.1 °C over the 30-min window (docs/clothing.md, \"The stop rule\")");
    cmd->add_flag("--require-flux-stability", o->require_flux_stability,
                  "Stricter still: every zone's flux drift and scatter over the window within manikin analyze's limits "
                  "(2 W/m², 5 W/m²)");
    cmd->add_option("--draws", o->options.monte_carlo_draws, "Monte Carlo draws for the Type B uncertainty")
        ->check(CLI::Range(100, 1000000))
        ->capture_default_str();
    cmd->footer("Trials take part when campaign.json names their `ensemble` (an id of `ensembles`, or \"nude\") and\n"
                "`test` (\"insulation\" or \"evaporative\"); docs/clothing.md has the equations, the standards' conditions\n"
                "and where each number comes from. Exit status 5 when a trial was left out (not steady by the rule, or\n"
                "not analysed; the table says which and why), 0 otherwise, even when a replicate criterion fails (reported).\n"
                "Example: manikin clothing lab-day --baseline nude-baseline --report report.html\n"
                "         manikin clothing quick-check --redress-from lab-day   # one replicate, the lab's re-dressing scatter\n"
                "         manikin clothing --db manikind.db --campaign jackets-20261126 --json");
    cmd->callback([o] {
        // The report is checked before anything is read (docs/cli.md, "Reading a database, writing
        // an export"): never in a campaign folder read (it could replace campaign.json or a trial's
        // CSV), never on a database read or any database's companion, links, devices, and an
        // existing file only with --force; written whole, then renamed into place.
        std::optional<ExportTarget> target;
        if (!o->report.empty()) {
            std::vector<std::filesystem::path> inputs = source_inputs(o->source);
            for (const std::string* other : {&o->baseline, &o->redress_from}) {
                if (other->empty()) continue;
                CampaignSource from = o->source;
                from.campaign = *other;
                for (auto& p : source_inputs(from)) inputs.push_back(std::move(p));
            }
            target.emplace(o->report, ExportShape::file, o->force, inputs);
        }
        const analysis::Campaign campaign = read_campaign_source(o->source);
        for (const auto& w : campaign.warnings) spdlog::warn("{}", w);
        analysis::AnalysisOptions analysis_options;
        analysis_options.steady.require_flux_stability = o->require_flux_stability;
        analysis_options.steady.require_heat_loss_stability = !o->skin_steadiness_only;
        const auto result = analysis::analyze_campaign(campaign, analysis_options);
        std::optional<analysis::Campaign> baseline;
        std::optional<analysis::CampaignResult> baseline_result;
        if (!o->baseline.empty()) {
            CampaignSource from = o->source;
            from.campaign = o->baseline;
            try {
                baseline = read_campaign_source(from);
            } catch (const UserError& e) {
                // Named as the baseline: "no campaign 'nude'" alone read as if the tested campaign were missing.
                throw UserError(fmt::format("--baseline '{}' (the nude manikin's campaign): {}", o->baseline, e.what()), e.code(),
                                e.status(), e.details());
            }
            baseline_result = analysis::analyze_campaign(*baseline, analysis_options);
        }
        analysis::clothing::Options options = o->options;
        options.cv_limit_insulation = o->cv_limit_insulation_pct / 100.0;
        options.cv_limit_evaporative = o->cv_limit_evaporative_pct / 100.0;
        if (!o->redress_from.empty()) {
            CampaignSource from = o->source;
            from.campaign = o->redress_from;
            try {
                const analysis::Campaign earlier = read_campaign_source(from);
                const auto earlier_result = analysis::analyze_campaign(earlier, analysis_options);
                analysis::clothing::Options plain = options;
                plain.monte_carlo_draws = 100;  // only its replicates are used
                options.redressing = analysis::clothing::redressing_scatter(
                    analysis::clothing::compute(earlier, earlier_result, nullptr, nullptr, plain));
            } catch (const UserError& e) {
                throw UserError(fmt::format("--redress-from '{}' (the earlier test with replicates): {}", o->redress_from, e.what()),
                                e.code(), e.status(), e.details());
            } catch (const std::invalid_argument& e) {
                throw UserError(fmt::format("--redress-from '{}': {}", o->redress_from, e.what()));
            }
        }
        analysis::clothing::Result r;
        try {
            r = analysis::clothing::compute(campaign, result, baseline ? &*baseline : nullptr,
                                            baseline_result ? &*baseline_result : nullptr, options);
        } catch (const std::invalid_argument& e) {
            throw UserError(e.what());
        }
        if (target) {
            {
                std::ofstream out(target->staging(), std::ios::binary | std::ios::trunc);
                out << analysis::clothing::to_html(r, campaign.zone_map);
                out.flush();
                if (!out) throw UserError(fmt::format("--report {}: write failed", o->report), "write_failed");
            }
            target->commit();
            spdlog::info("wrote {}", o->report);
        }
        if (o->json)
            std::printf("%s\n", analysis::clothing::to_json(r).dump(2).c_str());
        else
            std::printf("%s", analysis::clothing::to_text(r).c_str());
        // Trials left out change what the results stand on: the exit status says so (docs/cli.md).
        if (!r.left_out.empty() || !r.without_result.empty())
            throw UserError::verdict_in_output(fmt::format(
                "{} trial{} left out{}: see LEFT OUT in the table (or left_out in --json)", r.left_out.size(),
                r.left_out.size() == 1 ? "" : "s",
                r.without_result.empty() ? "" : fmt::format(", {} ensemble{} without a result", r.without_result.size(),
                                                            r.without_result.size() == 1 ? "" : "s")));
    });
}

}  // namespace manikind::cli
