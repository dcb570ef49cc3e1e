// `manikin reconcile <campaign>`: where the twin and the recordings disagree, which physics
// term explains it, and the fit before and after (analysis/reconcile).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <unistd.h>

#include <fmt/core.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "analysis/analyze.hpp"
#include "analysis/reconcile/from_analysis.hpp"
#include "analysis/reconcile/reconcile.hpp"
#include "analysis/reconcile/report_output.hpp"
#include "cli/campaign_source.hpp"
#include "cli/commands.hpp"
#include "cli/power_progress.hpp"
#include "analysis/reconcile/twin_store.hpp"
#include "base/user_error.hpp"
#include "physics/sign_convention.hpp"
#include "store/export_target.hpp"

namespace manikind::cli {
namespace {

namespace rc = analysis::reconcile;

}  // namespace

void add_reconcile_command(CLI::App& app) {
    struct Opts {
        CampaignSource source;
        std::string twin = "baseline", plots, write_twin, noise_from;
        bool json = false, no_pairs = false, power = false;
        double alpha = 0.01;
        int simulations = 2000;
        int power_campaigns = 40;
        int threads = 0;
        bool power_every_lab = false;
        std::vector<int> power_replicates = {3, 5, 10};
        std::vector<std::string> power_terms;
        std::string hypotheses = "default";
        std::uint64_t seed = 20261123;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("reconcile", "Find the physics the twin left out: locate the mismatch, fit candidate "
                                                "terms, show the fit improve");
    add_campaign_source_options(cmd, o->source);
    cmd->add_option("--twin", o->twin, "Twin version: 'baseline' (docs/twin-baseline.md) or a twin-version TOML file")
        ->capture_default_str();
    cmd->add_flag("--json", o->json, "Print one JSON document (docs/formats.md section 3) instead of the report");
    cmd->add_option("--plots", o->plots, "Write parity.svg, residual_vs_driver.svg, residual_body_map.svg (the standardised residual on the body, before and after) and residual_vs_height.svg into this folder");
    cmd->add_option("--write-twin", o->write_twin, "Write the new twin version (TOML) here when a term is found");
    cmd->add_flag("--no-pairs", o->no_pairs, "Fit single terms only");
    cmd->add_option("--hypotheses", o->hypotheses,
                    "Hypotheses generated from the twin's inputs and the body's geometry, beside the named terms: "
                    "'default' (a vertical air gradient, radiant asymmetry front/back/left/right and floor to ceiling, "
                    "the humidity probe and humidity by height, one side drier), 'all' (every input x pattern: a larger "
                    "family, a higher claim threshold) or 'none'")
        ->check(CLI::IsMember({"default", "all", "none"}))
        ->capture_default_str();
    cmd->add_option("--alpha", o->alpha, "False-claim rate: a term is claimed only when its evidence exceeds what "
                                          "noise alone reaches in this fraction of simulated campaigns")
        ->check(CLI::Range(0.0001, 0.2))
        ->capture_default_str();
    cmd->add_option("--simulations", o->simulations, "Campaigns simulated under the twin for the null distribution")
        ->check(CLI::Range(200, 100000))
        ->capture_default_str();
    cmd->add_option("--seed", o->seed, "Seed of the simulations (results are reproducible)")->capture_default_str();
    cmd->add_option("--noise-from", o->noise_from,
                    "Carry the lab's replicate scatter from an earlier campaign with replicates (a folder, or with --db a "
                    "campaign in the same database) for a campaign with one replicate per case: without it no claim "
                    "is made there (docs/reconcile.md, \"One replicate\")");
    cmd->add_flag("--power", o->power, "Plan instead: per candidate, the smallest effect named with 80 % power for "
                                       "this campaign's cases and noise, at its replicates and at --power-replicates; "
                                       "each checked by running reconcile on campaigns of this design drawn anew "
                                       "(named: alone, or beside a drawn probe's own calibration error; with "
                                       "--no-pairs, planned for reconcile without pairs); and which limits hang on "
                                       "how far a probe or the manikin's calibration erred within its spec, with the "
                                       "limit a calibration to half the spec would reach");
    cmd->add_option("--power-replicates", o->power_replicates, "Replicates per case to plan for (with --power)")
        ->check(CLI::Range(1, 30))
        ->delimiter(',')
        ->capture_default_str();
    cmd->add_option("--power-campaigns", o->power_campaigns,
                    "Simulated campaigns through the whole decision per effect size tried (with --power); 0: the fast "
                    "model's check only")
        ->check(CLI::Range(0, 1000))
        ->capture_default_str();
    cmd->add_flag("--power-every-lab", o->power_every_lab,
                  "Reconcile every drawn campaign at every value tried (with --power). By default a drawn lab that "
                  "named the term at a value is taken to name it at a larger one, and one that missed it to miss "
                  "it at a smaller one; with this flag each is reconciled, and --json counts the labs that broke "
                  "that order (non_monotone_labs)");
    cmd->add_option("--threads", o->threads,
                    "Threads the drawn campaigns are reconciled on (with --power; 0: one per core); the answer does not "
                    "depend on it")
        ->check(CLI::Range(0, 256))
        ->capture_default_str();
    cmd->add_option("--power-terms", o->power_terms,
                    "Plan only these candidates (a term such as humidity_buoyancy, or term:region), comma-separated "
                    "(with --power; default: every named candidate; a generated one such as input_pattern:air_temp_c/height "
                    "only when named here)")
        ->delimiter(',');
    cmd->footer("The twin sees only the campaign's recorded conditions. The noise of every case mean comes from the\n"
                "recordings: replicate scatter pooled per zone, the manikin's calibration shared by all points, each\n"
                "case's probe errors shared by its zones (campaign.json `instruments`). A term is claimed only beyond\n"
                "the evidence noise alone reaches (--alpha), chosen out of sample by case, and told apart from its\n"
                "rivals; otherwise the report says where the mismatch is and that it is unexplained. A steady offset\n"
                "on a few zones is reported as a local anomaly, not physics. docs/reconcile.md has the equations.\n"
                "Heat flux: " + std::string(physics::heat_flux_sign) + ".\n"
                "Exit status 0 whether or not a term is found (docs/cli.md).\n"
                "Example: manikin simulate-campaign --effect humidity_buoyancy:gamma=146 --out /tmp/c\n"
                "         manikin reconcile /tmp/c --plots /tmp/c/plots --write-twin /tmp/c/twin.toml\n"
                "         manikin reconcile --db manikind-demo/manikind.db --campaign validation-20261124T010203Z");
    cmd->callback([o] {
        const auto t0 = std::chrono::steady_clock::now();
        const auto base = twin_store::load_twin_version(o->twin);
        {
            // What it writes is checked before anything is read: never a database or its companions,
            // never what it reads (docs/cli.md). A folder read protects its recording, campaign.json
            // and trials/, not the whole folder: the docs put --plots inside the campaign folder.
            std::vector<std::filesystem::path> inputs;
            for (const std::string& name : {o->source.campaign, o->noise_from}) {
                if (name.empty()) continue;
                CampaignSource from = o->source;
                from.campaign = name;
                for (const auto& in : source_inputs(from)) {
                    if (from.db.empty() && std::filesystem::is_directory(in)) {
                        inputs.push_back(in / "campaign.json");
                        inputs.push_back(in / "trials");
                    } else {
                        inputs.push_back(in);
                    }
                }
            }
            if (!o->plots.empty()) {
                refuse_protected_output(o->plots, inputs);
                for (const auto& p : rc::plot_file_names()) refuse_protected_output(std::filesystem::path(o->plots) / p, inputs);
            }
            if (!o->write_twin.empty()) refuse_protected_output(o->write_twin, inputs);
        }
        const analysis::Campaign campaign = read_campaign_source(o->source);
        // With --db the positional names a campaign in it, otherwise a folder: report what was read.
        const std::string campaign_label = !o->source.archive.empty() ? "archive lab " + o->source.lab + ": " + campaign.name
                                            : o->source.db.empty()    ? o->source.campaign
                                                                      : o->source.db + ": " + campaign.name;
        for (const auto& w : campaign.warnings) spdlog::warn("{}", w);
        const auto result = analysis::analyze_campaign(campaign);
        std::vector<int> skipped;
        auto cases = rc::case_inputs_from_results(result, campaign.zone_map, &skipped);
        for (int id : skipped) spdlog::warn("case {}: no air temperature or humidity in the steady window; left out", id);
        if (cases.empty()) throw UserError(fmt::format("{}: no case has a steady window to compare", campaign_label));
        std::optional<rc::CarriedNoise> carried;
        if (!o->noise_from.empty()) {
            CampaignSource from = o->source;
            from.campaign = o->noise_from;
            const analysis::Campaign earlier = read_campaign_source(from);
            const auto earlier_result = analysis::analyze_campaign(earlier);
            auto earlier_cases = rc::case_inputs_from_results(earlier_result, earlier.zone_map);
            if (earlier_cases.empty()) throw UserError(fmt::format("--noise-from {}: no case has a steady window", o->noise_from));
            const auto earlier_model = rc::make_twin_model(std::move(earlier_cases), base);
            try {
                carried = rc::carried_noise(*earlier_model, earlier.instruments, earlier.name.empty() ? o->noise_from : earlier.name);
            } catch (const std::invalid_argument& e) {
                throw UserError(fmt::format("--noise-from {}", e.what()));
            }
        }
        const auto model = rc::make_twin_model(std::move(cases), base, std::move(carried));
        rc::Options opt;
        opt.try_pairs = !o->no_pairs;
        opt.hypotheses = o->hypotheses;
        opt.alpha = o->alpha;
        opt.null_simulations = o->simulations;
        opt.seed = o->seed;
        opt.instruments = campaign.instruments;
        if (o->power) {
            rc::PowerOptions po;
            po.campaigns = o->power_campaigns;
            po.threads = o->threads;
            po.every_lab = o->power_every_lab;
            // On stderr, so --json's stdout stays one document: a bar with the time left on a
            // terminal, a line every 10 s in a log.
            auto meter = std::make_shared<PowerProgressMeter>(stderr, ::isatty(STDERR_FILENO) != 0);
            po.progress = [meter](const rc::PowerProgress& p) { meter->update(p); };
            po.terms = o->power_terms;
            rc::PowerReport plan;
            try {
                plan = rc::detection_limits(*model, opt, o->power_replicates, po);
            } catch (const std::invalid_argument& e) {
                meter->finish();
                throw UserError(fmt::format("--power-terms: {}", e.what()));
            }
            meter->finish();
            const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            if (o->json) {
                nlohmann::json j = rc::power_to_json(plan);
                j["campaign"] = campaign_label;
                j["seconds"] = seconds;
                std::printf("%s\n", j.dump(2).c_str());
            } else {
                std::printf("Campaign: %s (%zu cases, %d replicates)\n%s(%.2f s)\n", campaign_label.c_str(), result.cases.size(),
                            plan.campaign_replicates, rc::power_to_text(plan).c_str(), seconds);
            }
            return;
        }
        opt.new_version_name = fmt::format("{}+reconciled", base.name);
        if (model->points().empty()) {
            // Nothing to fit is the campaign's state, not a bug: say why (issue 61's screen can leave none).
            std::string why;
            for (const auto& m : model->measurement()) why += "; " + m;
            throw UserError(fmt::format("{}: no case and zone has a finite flux with an uncertainty to reconcile{}", campaign_label,
                                        why));
        }
        auto report = rc::reconcile(*model, opt);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (!o->plots.empty()) {
            for (const auto& p : rc::write_plots(report, *model, o->plots)) spdlog::info("wrote {}", p.string());
        }
        if (!o->write_twin.empty() && report.explanation) {
            twin_store::save_twin_version(report.new_version, o->write_twin, base.name,
                                          fmt::format("found by manikin reconcile {}", campaign_label));
            spdlog::info("wrote twin version {}", o->write_twin);
        }
        if (o->json) {
            auto j = rc::report_to_json(report, *model);
            j["campaign"] = campaign_label;
            j["heat_flux_sign"] = physics::heat_flux_sign;
            j["seconds"] = seconds;
            std::printf("%s\n", j.dump(2).c_str());
        } else {
            std::printf("Campaign: %s (%zu cases); heat flux %s\n%s", campaign_label.c_str(), result.cases.size(),
                        physics::heat_flux_sign,
                        rc::report_to_text(report).c_str());
            std::printf("(%.2f s)\n", seconds);
        }
    });
}

}  // namespace manikind::cli
