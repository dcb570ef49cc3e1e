// `manikin demo`: the README's main job. Runs the paper's validation campaign (Table S3, 15 cases
// x 3 replicates, 75 min each) through the daemon on the simulated lab (every device over its
// real transport, virtual clock, SQLite recorder), analyses it from the database (steady state,
// GUM uncertainty, 95 % CIs), and asks reconcile what the baseline twin is missing.
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"
#include "analysis/reconcile/from_analysis.hpp"
#include "analysis/reconcile/reconcile.hpp"
#include "analysis/reconcile/report_output.hpp"
#include "cli/commands.hpp"
#include "store/database_export.hpp"
#include "daemon/virtual_run.hpp"
#include "store/database.hpp"
#include "base/user_error.hpp"
#include "analysis/reconcile/twin_store.hpp"
#include "physics/sign_convention.hpp"

namespace manikind::cli {

void add_demo_command(CLI::App& app) {
    struct Opts {
        std::string out = "manikind-demo";
        std::uint64_t seed = 2026;
        bool json = false;
        int cases = 15;
        int replicates = 3;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("demo", "Simulated validation campaign (Table S3 x 3) -> heat fluxes with 95 % CIs -> "
                                           "what the twin is missing");
    cmd->add_option("--out", o->out, "Folder for the database, recordings, results and plots (its database is replaced)")
        ->capture_default_str();
    cmd->add_option("--seed", o->seed, "Random seed of the simulated lab")->capture_default_str();
    cmd->add_flag("--json", o->json, "Print the analysis and reconcile JSON documents");
    cmd->add_option("--cases", o->cases, "Run only the first N cases of Table S3")->check(CLI::Range(1, 15))->capture_default_str();
    cmd->add_option("--replicates", o->replicates, "Replicates per case")->check(CLI::Range(1, 5))->capture_default_str();
    cmd->footer("The simulated world includes humidity-driven buoyancy (gamma = 146, the paper's finding);\n"
                "the baseline twin does not. Nothing in the analysis is told so.\n"
                "Heat flux: " + std::string(physics::heat_flux_sign) + ".");
    cmd->callback([o] {
        namespace rc = analysis::reconcile;
        const auto t0 = std::chrono::steady_clock::now();
        const std::filesystem::path out(o->out);
        std::filesystem::create_directories(out);
        config::Config cfg = config::default_config();
        cfg.database = out / "manikind.db";
        // The demo's folder is its own scratch space: each run starts a fresh database (~300 MB).
        for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(out / (std::string("manikind.db") + suffix));
        cfg.simulation.seed = o->seed;
        cfg.simulation.runtime_dir = (out / "sim").string();
        cfg.log_level = "warn";
        // The paper logged every 5 s (Text S3.2): poll and step the virtual clock at that pace.
        cfg.devices.poll_period_s = 5.0;
        cfg.simulation.step_s = 5.0;
        CampaignPlan plan = table_s3_plan("");
        plan.cases.resize(static_cast<std::size_t>(o->cases));
        plan.replicates = o->replicates;
        char stamp[32];
        const std::time_t now = std::time(nullptr);
        std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%SZ", std::gmtime(&now));
        plan.name = std::string("validation-") + stamp;
        if (!o->json)
            std::printf("manikind demo: the paper's validation campaign through the daemon on the simulated lab\n"
                        "  %zu cases x %d replicates; every device over its real transport, virtual clock\n",
                        plan.cases.size(), plan.replicates);
        const VirtualRun run = run_virtual_campaign(cfg, plan, [&](const std::string& line) {
            if (!o->json) std::fprintf(stderr, "  %s\n", line.c_str());
        });
        // The campaign as the daemon read it for its results; read here only if it has none.
        std::shared_ptr<const analysis::Campaign> read = run.campaign;
        if (!read) {
            auto db = recorder::Database::open(run.database);
            read = std::make_shared<const analysis::Campaign>(campaign_from_database(db, plan.name));
        }
        const analysis::Campaign& campaign = *read;
        analysis::write_campaign(out / "campaign", campaign);
        int unsteady = 0;
        const auto t_sim = std::chrono::steady_clock::now();

        const auto result = analysis::analyze_campaign(campaign);
        const auto t_analysis = std::chrono::steady_clock::now();
        const auto model = rc::make_twin_model(rc::case_inputs_from_results(result, campaign.zone_map), {});
        const auto report = rc::reconcile(*model);
        rc::write_plots(report, *model, out / "plots");
        if (report.explanation)
            twin_store::save_twin_version(report.new_version, out / "twin-reconciled.toml", "baseline", "found by manikin demo");
        const auto t_end = std::chrono::steady_clock::now();
        auto secs = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };

        if (o->json) {
            std::printf("%s\n", nlohmann::json{{"heat_flux_sign", physics::heat_flux_sign},
                                               {"analysis", analysis::to_json(result)},
                                               {"reconcile", rc::report_to_json(report, *model)}}
                                    .dump(2)
                                    .c_str());
            return;
        }
        (void)unsteady;
        std::printf("  %zu trials recorded in %.1f s of wall time (%.0f h of virtual lab time)\n", campaign.trials.size(),
                    secs(t0, t_sim), run.lab_time_s / 3600.0);
        std::printf("  database:   %s (campaign '%s')\n", run.database.string().c_str(), plan.name.c_str());
        std::printf("  recordings: %s\n\n", (out / "campaign").string().c_str());
        // Compact results table: whole body per case with its 95 % CI (manikin analyze has the rest).
        std::printf("Whole-body heat flux per case (%s), mean of the replicates with 95 %% CI:\n", physics::heat_flux_sign);
        std::printf("  case  T_air °C  RH_air %%  T_skin °C  wet  n   Q_WB W/m²   U (95 %%)     k\n");
        std::vector<std::string> excluded;
        for (const auto& c : result.cases) {
            auto cond = [&](const char* ch) { return rc::case_condition(c, ch); };
            std::printf("  %4d  %8.2f  %8.1f  %9.2f  %3.0f  %d  %9.2f  %9.2f  %6.3f\n", c.case_id, cond("air_temp_c"),
                        cond("air_rh_pct"), cond("skin_temp_c"), c.wettedness.value_or(0.0), c.n_replicates,
                        c.whole_body.q.value, c.whole_body.q.U, c.whole_body.q.k);
            for (const auto& t : c.trials)
                if (!t.included) excluded.push_back(fmt::format("{} ({})", t.id, t.exclusion_reason));
        }
        for (const auto& e : excluded) std::printf("  excluded: %s\n", e.c_str());
        std::printf("  (regions, zones and uncertainty budgets: manikin analyze %s)\n\n", (out / "campaign").string().c_str());

        std::printf("Reconcile against the baseline twin (temperature-driven free convection only):\n");
        std::printf("  before: RMSE %.2f W/m², chi2/dof %.1f, %d of %d zone results outside their 95 %% CI\n",
                    report.before.rmse, report.before.chi2_per_dof, report.before.outside_ci, report.before.n_points);
        if (!report.located.empty())
            std::printf("  located: %s; strongest driver %s (|r| = %.2f)\n", report.located[0].where.c_str(),
                        report.located[0].driver.c_str(), report.located[0].strength);
        std::printf("  %s\n", report.statement.c_str());
        if (report.explanation)
            std::printf("  after:  RMSE %.2f W/m², chi2/dof %.2f, %d outside; leave-one-case-out RMSE %.2f W/m²\n",
                        report.after.rmse, report.after.chi2_per_dof, report.after.outside_ci,
                        report.explanation->loo_rmse.value_or(NAN));
        std::printf("  (full report: manikin reconcile %s)\n", (out / "campaign").string().c_str());
        std::printf("Plots: %s (parity, residual by driver and by height, the residual on the body map)\n",
                    (out / "plots").string().c_str());
        if (report.explanation) std::printf("New twin version: %s\n", (out / "twin-reconciled.toml").string().c_str());
        std::printf("Timing: simulate %.2f s, analyse %.2f s, reconcile %.2f s\n", secs(t0, t_sim), secs(t_sim, t_analysis),
                    secs(t_analysis, t_end));
    });
}

}  // namespace manikind::cli
