// `manikin physio <campaign>`: a physiological trial's trajectories (issue 34): the model's core
// and mean skin temperature, the measured heat loss and the sweat, with 95 % bands, beside the
// model alone in the same recorded conditions (analysis/physio.hpp). Fig. 4 from measured data.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "analysis/physio.hpp"
#include "base/user_error.hpp"
#include "cli/campaign_source.hpp"
#include "cli/commands.hpp"
#include "store/export_target.hpp"

namespace manikind::cli {

void add_physio_command(CLI::App& app) {
    struct Opts {
        CampaignSource source;
        std::string plot;
        bool json = false, force = false;
        double every_min = 10.0;
        analysis::physio::Options options;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("physio", "A physiological trial's trajectories (core, mean skin, heat loss, sweat) with "
                                             "95 % bands, beside the model alone in the recorded conditions");
    add_campaign_source_options(cmd, o->source);
    cmd->add_flag("--json", o->json, "Print one JSON document (every coupling step of every trial and case)");
    cmd->add_option("--plot", o->plot, "Write Fig. 4 from measured data (SVG) to this file (new; --force replaces)");
    cmd->add_flag("--force", o->force, "Replace an existing plot file");
    cmd->add_option("--every", o->every_min, "Rows of the table every this many minutes of model time")
        ->check(CLI::Range(0.1, 600.0))
        ->capture_default_str();
    cmd->add_option("--draws", o->options.draws, "Monte Carlo draws for the Type B band (replays of the model)")
        ->check(CLI::Range(20, 100000))
        ->capture_default_str();
    cmd->footer("A trial run with control = \"physiological\" records the model as device `model` (docs/thermoregulation.md,\n"
                "\"The manikin in the loop\"); this replays the model from those records: the band is Type B from the\n"
                "instruments' specifications (the heat flux's gain and offset common to the zones, the probes' offsets)\n"
                "and, with replicates, Type A; \"a further run\" is where another run on this manikin and chamber is\n"
                "expected (95 %, from the replicates' spread). \"alone\" is the model with its own heat exchange in the\n"
                "recorded air, humidity, walls and air speed, with its band from the probes' specifications; the loop\n"
                "agrees with it where their difference is within the difference's band (the same drawn errors in both).\n"
                "Example: manikin physio --db manikind.db --campaign heat-stress --plot fig4-measured.svg");
    cmd->callback([o] {
        // The plot is checked before anything is read: never in the campaign folder read, on the
        // database read or any database's companion, --force or not (docs/cli.md).
        std::optional<ExportTarget> target;
        if (!o->plot.empty()) target.emplace(o->plot, ExportShape::file, o->force, source_inputs(o->source));
        const analysis::Campaign campaign = read_campaign_source(o->source);
        for (const auto& w : campaign.warnings) spdlog::warn("{}", w);
        const auto r = analysis::physio::compute(campaign, o->options);
        if (r.trials.empty())
            throw UserError(fmt::format("{}: no physiological trial (none recorded the model's channels: run cases with "
                                        "control = \"physiological\")",
                                        campaign.name),
                            "no_physiological_trials");
        if (target) {
            {
                std::ofstream out(target->staging(), std::ios::binary | std::ios::trunc);
                out << analysis::physio::svg(r, campaign.name + ": the manikin under the model's control");
                out.flush();
                if (!out) throw UserError(fmt::format("--plot {}: write failed", o->plot), "write_failed");
            }
            target->commit();
            spdlog::info("wrote {}", o->plot);
        }
        if (o->json) {
            std::printf("%s\n", analysis::physio::to_json(r).dump(2).c_str());
            return;
        }
        for (const auto& t : r.trials)
            std::printf("trial %s (case %d replicate %d): coupled every %.0f s, %zu steps%s; replay reproduces the recorded "
                        "model within %.1e °C\n",
                        t.trial.c_str(), t.case_id, t.replicate, t.coupling_period_s, t.points.size(),
                        t.fell_back ? ", FELL BACK to constant skin (shown up to then)" : "", t.replay_max_abs_diff_c);
        for (const auto& c : r.cases) {
            const bool further = c.replicates >= 2;
            std::printf("\ncase %d (%d replicate%s), 95 %% bands:\n", c.case_id, c.replicates, c.replicates == 1 ? "" : "s");
            std::printf("  %6s  %15s  %15s  %14s  %9s  %17s  %17s%s\n", "min", "core °C", "mean skin °C", "heat loss W", "sweat g/h",
                        "alone skin °C", "loop - alone °C", further ? "  a further run ± core/skin °C" : "");
            double next_s = 0.0;
            for (std::size_t k = 0; k < c.points.size(); ++k) {
                const auto& p = c.points[k];
                if (p.t_s + 1e-9 < next_s && k + 1 != c.points.size()) continue;
                next_s = p.t_s + o->every_min * 60.0 - 1e-9;
                std::printf("  %6.0f  %7.2f ± %5.2f  %7.2f ± %5.2f  %6.0f ± %5.0f  %9.0f  %8.2f ± %5.2f  %+8.2f ± %5.2f", p.t_s / 60.0,
                            p.core_temp_c, p.core_u95_c, p.mean_skin_temp_c, p.mean_skin_u95_c, p.heat_loss_w,
                            p.heat_loss_u95_w, p.sweat_rate_g_h, p.alone_coupled_skin_c, p.alone_skin_u95_c,
                            p.mean_skin_temp_c - p.alone_coupled_skin_c, p.diff_skin_u95_c);
                if (further) std::printf("  %12.2f / %-5.2f", p.core_repro_u95_c, p.skin_repro_u95_c);
                std::printf("\n");
            }
            const auto& a = c.agreement;
            if (a.points > 0)
                std::printf("  against the model alone (coupled) in the recorded conditions: the difference is within its band at "
                            "%d of %d steps in mean skin and %d of %d in core (largest mean-skin difference %.2f °C, band ± %.2f): "
                            "%s\n",
                            a.skin_within, a.points, a.core_within, a.points, a.worst_skin_c, a.worst_skin_u95_c,
                            a.agrees ? "agrees (at least 95 % of the steps in both)"
                                     : "departs beyond what the probes allow (the measured exchange is not the model's own)");
        }
    });
}

}  // namespace manikind::cli
