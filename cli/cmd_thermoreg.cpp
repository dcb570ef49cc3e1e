// `manikin thermoreg`: the paper's thermoregulation model (Fig. 4), its S22 sweep and S23
// air-speed study.
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <future>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "analysis/plot/svg_figure.hpp"
#include "cli/commands.hpp"
#include "base/user_error.hpp"
#include "physics/sign_convention.hpp"
#include "physics/thermoreg/stolwijk.hpp"
#include "store/export_target.hpp"

namespace manikind::cli {
namespace {

namespace tr = physics::thermoreg;

double parse_duration_s(const std::string& text) {
    std::size_t used = 0;
    double value = 0.0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    const std::string unit = text.substr(used);
    double scale = 0.0;
    if (unit.empty() || unit == "s") scale = 1.0;
    else if (unit == "min" || unit == "m") scale = 60.0;
    else if (unit == "h") scale = 3600.0;
    if (used == 0 || scale == 0.0 || !(value > 0.0))
        throw UserError(fmt::format("--duration '{}': expected a positive number with s, min or h (e.g. 2h, 90min, 7200s)", text));
    return value * scale;
}

tr::ConvectionModel parse_model(const std::string& name) {
    if (name == "coupled") return tr::ConvectionModel::coupled;
    if (name == "dt-only") return tr::ConvectionModel::dt_only;
    if (name == "constant" || name == "constant-stolwijk") return tr::ConvectionModel::constant_stolwijk;
    if (name == "constant-jos") return tr::ConvectionModel::constant_jos;
    throw UserError(fmt::format("--convection '{}': expected coupled, dt-only, constant (Stolwijk) or constant-jos", name));
}

tr::SimulationResult run_checked(const tr::Exposure& e, const tr::ModelOptions& o) {
    try {
        return tr::simulate(e, o);
    } catch (const std::domain_error& err) {
        throw UserError(err.what());
    }
}

// The model keeps Fig. 4's sign (positive = gained by the body); everything this command prints
// follows the CLI's one convention instead (physics::heat_flux_sign), converted here only.
struct PrintedRates {
    double evaporation_loss_w, convection_loss_w, radiation_loss_w, respiration_loss_w;  // positive = heat lost
    double metabolic_production_w;  // heat generated in the body
    double storage_w;               // positive = heat stored in the body
};

PrintedRates printed_rates(const tr::OutputSample& s) {
    return {-s.evaporation_w, -s.convection_w, -s.radiation_w, -s.respiration_w, s.metabolic_w, s.storage_w};
}

const std::string& rates_sign_text() {
    static const std::string text = fmt::format("heat losses {}; metabolic = heat produced; {}", physics::heat_flux_sign,
                                                physics::heat_storage_sign);
    return text;
}

nlohmann::json sample_json(const tr::OutputSample& s) {
    const auto p = printed_rates(s);
    return {{"t_s", s.t_s},
            {"core_temp_c", s.core_temp_c},
            {"mean_skin_temp_c", s.mean_skin_temp_c},
            {"evaporation_loss_w", p.evaporation_loss_w},
            {"convection_loss_w", p.convection_loss_w},
            {"radiation_loss_w", p.radiation_loss_w},
            {"respiration_loss_w", p.respiration_loss_w},
            {"metabolic_production_w", p.metabolic_production_w},
            {"storage_w", p.storage_w},
            {"buoyancy_drive_c", s.mean_buoyancy_drive_c},
            {"mean_skin_wettedness", s.mean_skin_wettedness}};
}

// Fig. 4: temperatures (top) and heat rates with 50 x (dT + 146 dC) (bottom) against time.
std::string fig4_svg(const tr::SimulationResult& r, const std::string& title) {
    namespace pl = analysis::plot;
    pl::Figure fig;
    fig.width_px = 760;
    fig.height_px = 720;
    fig.title = title;
    std::vector<double> t_min;
    for (const auto& s : r.series) t_min.push_back(s.t_s / 60.0);
    auto trace = [&](const std::string& label, const std::string& colour, auto value_of) {
        pl::Series s;
        s.label = label;
        s.colour = colour;
        s.line = true;
        s.markers = false;
        s.x = t_min;
        for (const auto& sample : r.series) s.y.push_back(value_of(sample));
        return s;
    };
    auto time_axis = [&] {
        pl::Axis a;
        a.label = "Time (min)";
        a.lo = 0.0;
        a.hi = t_min.empty() ? 1.0 : t_min.back();
        a.target_intervals = 6;
        return a;
    };
    pl::XYPanel temps;
    temps.box = {0, 34, 760, 320};
    temps.x = time_axis();
    temps.y.label = "Temperature (°C)";
    temps.series = {trace("core", "#d62728", [](const auto& s) { return s.core_temp_c; }),
                    trace("mean skin", "#1f77b4", [](const auto& s) { return s.mean_skin_temp_c; })};
    pl::XYPanel heat;
    heat.box = {0, 364, 760, 350};
    heat.x = time_axis();
    heat.y.label = "Heat rate (W): losses + = lost, storage + = stored";
    heat.y.target_intervals = 8;
    heat.reference_lines.push_back({true, 0.0, "#999999", ""});
    heat.series = {trace("evaporation loss", "#1f77b4", [](const auto& s) { return printed_rates(s).evaporation_loss_w; }),
                   trace("radiation loss", "#ff7f0e", [](const auto& s) { return printed_rates(s).radiation_loss_w; }),
                   trace("convection loss", "#2ca02c", [](const auto& s) { return printed_rates(s).convection_loss_w; }),
                   trace("metabolic production", "#9467bd", [](const auto& s) { return printed_rates(s).metabolic_production_w; }),
                   trace("storage (+ = stored)", "#d62728", [](const auto& s) { return printed_rates(s).storage_w; }),
                   trace("50 × (dT + 146 dC)", "#7f7f7f", [](const auto& s) { return 50.0 * s.mean_buoyancy_drive_c; })};
    heat.series.back().dash = "5 4";
    // Both legends right of the plots: six traces leave no free corner below, and the two time
    // axes stay aligned.
    for (auto* panel : {&temps, &heat}) {
        panel->legend_outside = true;
        panel->min_left_margin_px = 70.0;
        panel->min_legend_width_px = 170.0;
    }
    fig.xy_panels = {std::move(temps), std::move(heat)};
    return pl::to_svg(fig);
}

// Fig. S22's third column: coupled minus dt-only after 2 h over the T x RH grid.
std::string sweep_map_svg(const std::vector<double>& air_temps_c, const std::vector<double>& rhs_pct,
                          const std::vector<double>& diff_c, const std::string& what, const std::string& mrt) {
    namespace pl = analysis::plot;
    pl::Figure fig;
    fig.width_px = 720;
    fig.height_px = 540;
    fig.title = fmt::format("{} temperature difference, coupled − dt-only, after 2 h (MRT {})", what, mrt);
    fig.notes.push_back("red: the coupled model ends warmer; blue: cooler");
    pl::HeatMapPanel map;
    map.box = {0, 46, 720, 494};
    map.x.label = "Air temperature (°C)";
    map.y.label = "Relative humidity (%)";
    map.x_centres = air_temps_c;
    map.y_centres = rhs_pct;
    map.values = diff_c;
    for (std::size_t i = 0; i < diff_c.size(); ++i)
        map.tooltips.push_back(fmt::format("{} °C, {} %: {:+.2f} °C", air_temps_c[i / rhs_pct.size()],
                                           rhs_pct[i % rhs_pct.size()], diff_c[i]));
    map.scale_label = what + " difference (°C)";
    fig.heat_maps.push_back(std::move(map));
    return pl::to_svg(fig);
}

void write_text(const std::string& path, const std::string& text) {
    refuse_protected_output(path, {});  // a simulation reads no database, but never writes over one
    std::ofstream f(path, std::ios::binary);
    f << text;
    if (!f) throw UserError(fmt::format("{}: cannot write", path));
}

struct RunOpts {
    tr::Exposure exposure;
    std::string duration = "2h", convection = "coupled", csv, plot;
    bool seed_compatible = false, json = false;
    double clo = tr::default_clo;
};

void add_exposure_options(CLI::App* cmd, RunOpts& o) {
    cmd->add_option("--air-temp", o.exposure.air_temp_c, "Air temperature, °C")->capture_default_str();
    cmd->add_option("--rh", o.exposure.rh_pct, "Relative humidity, %")->capture_default_str();
    cmd->add_option("--mrt", o.exposure.mrt_c, "Mean radiant temperature, °C")->capture_default_str();
    cmd->add_option("--air-speed", o.exposure.air_speed.speed_m_s, "Air speed, m/s (mixed convection, Eq. 9)")->capture_default_str();
    cmd->add_option("--square-wave-period", o.exposure.air_speed.square_wave_period_s,
                    "Alternate the air speed with still air, period in s (Fig. S23B; 0 = constant)")->capture_default_str();
    cmd->add_option("--met", o.exposure.met, "Metabolic rate, met")->capture_default_str();
    cmd->add_option("--duration", o.duration, "Exposure, e.g. 2h, 90min, 7200s")->capture_default_str();
    cmd->add_option("--step", o.exposure.time_step_s, "Time step, s (explicit scheme; at most 5 s)")->capture_default_str();
    cmd->add_option("--convection", o.convection, "coupled | dt-only | constant | constant-jos")->capture_default_str();
    cmd->add_flag("--seed-compatible", o.seed_compatible, "Reproduce the published MATLAB code exactly (docs/thermoregulation.md)");
    cmd->add_option("--clo", o.clo,
                    "Whole-body clothing insulation, clo: the model's clothing (trunk, legs, feet) scaled to it; 0 = "
                    "bare, as the manikin undressed")
        ->check(CLI::Range(0.0, 4.0))
        ->capture_default_str();
}

}  // namespace

void add_thermoreg_command(CLI::App& app) {
    auto o = std::make_shared<RunOpts>();
    auto* cmd = app.add_subcommand("thermoreg", "Human thermoregulation (the paper's Stolwijk model): Fig. 4, sweeps, air speed");
    add_exposure_options(cmd, *o);
    cmd->add_flag("--json", o->json, "Print the time series as JSON (docs/formats.md section 4)");
    cmd->add_option("--csv", o->csv, "Write the time series as CSV");
    cmd->add_option("--plot", o->plot, "Write a Fig. 4-like SVG");
    cmd->footer("Defaults are Fig. 4: 41 °C, 20 % RH, MRT 55 °C, still air, 1.5 met, 0.26 clo, 2 h.\n"
                "Heat rates: " + rates_sign_text() + "\n(Fig. 4 plots the opposite sign). Core = trunk core.\n"
                "Examples:\n  manikin thermoreg --seed-compatible --plot fig4.svg\n"
                "  manikin thermoreg --convection dt-only --mrt 41 --json\n"
                "  manikin thermoreg sweep --mrt 55 --out s22/\n  manikin thermoreg speeds");
    cmd->callback([o, cmd] {
        if (!cmd->get_subcommands().empty()) return;  // a subcommand ran
        o->exposure.duration_s = parse_duration_s(o->duration);
        tr::ModelOptions m{parse_model(o->convection), o->seed_compatible, o->clo};
        const auto t0 = std::chrono::steady_clock::now();
        const auto r = run_checked(o->exposure, m);
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        if (!o->csv.empty()) {
            std::ostringstream csv;
            csv << "t_s,core_temp_c,mean_skin_temp_c,evaporation_loss_w,convection_loss_w,radiation_loss_w,respiration_loss_w,"
                   "metabolic_production_w,storage_w,buoyancy_drive_c,mean_skin_wettedness\n";
            for (const auto& s : r.series) {
                const auto p = printed_rates(s);
                csv << fmt::format("{},{:.4f},{:.4f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.4f},{:.4f}\n", s.t_s, s.core_temp_c,
                                   s.mean_skin_temp_c, p.evaporation_loss_w, p.convection_loss_w, p.radiation_loss_w,
                                   p.respiration_loss_w, p.metabolic_production_w, p.storage_w, s.mean_buoyancy_drive_c,
                                   s.mean_skin_wettedness);
            }
            write_text(o->csv, csv.str());
        }
        const std::string title = fmt::format("{} °C, {} % RH, MRT {} °C, {} m/s: {}{}", o->exposure.air_temp_c, o->exposure.rh_pct,
                                              o->exposure.mrt_c, o->exposure.air_speed.speed_m_s, tr::to_string(m.convection),
                                              m.seed_compatible ? " (seed-compatible)" : "");
        if (!o->plot.empty()) write_text(o->plot, fig4_svg(r, title));
        if (o->json) {
            nlohmann::json series = nlohmann::json::array();
            for (const auto& s : r.series) series.push_back(sample_json(s));
            std::printf("%s\n", nlohmann::json{{"convection", tr::to_string(m.convection)}, {"seed_compatible", m.seed_compatible},
                                               {"clo", m.clo},
                                               {"heat_flux_sign", rates_sign_text()},
                                               {"series", series}, {"final", sample_json(r.final)},
                                               {"max_energy_residual_w", r.max_abs_energy_residual_w}, {"compute_ms", ms}}
                                    .dump(2)
                                    .c_str());
            return;
        }
        std::printf("%s\nHeat rates: %s\n", title.c_str(), rates_sign_text().c_str());
        std::printf("  min   core °C   skin °C   evap W   conv W   rad W   metab W   storage W   dT+146dC\n");
        for (const auto& s : r.series)
            if (std::fmod(s.t_s, 600.0) < 1e-9) {
                const auto p = printed_rates(s);
                std::printf("  %3.0f   %7.2f   %7.2f   %6.0f   %6.0f   %5.0f   %7.0f   %9.0f   %8.2f\n", s.t_s / 60.0,
                            s.core_temp_c, s.mean_skin_temp_c, p.evaporation_loss_w, p.convection_loss_w, p.radiation_loss_w,
                            p.metabolic_production_w, p.storage_w, s.mean_buoyancy_drive_c);
            }
        std::printf("final (%.0f min): core %.2f °C, mean skin %.2f °C; energy balance closes to %.1e W; %.1f ms\n",
                    r.final.t_s / 60.0, r.final.core_temp_c, r.final.mean_skin_temp_c, r.max_abs_energy_residual_w, ms);
    });

    // ---- S22: the T x RH grid, both convection models ----
    struct SweepOpts {
        std::string mrt = "air", out = "thermoreg-sweep";
        double t_step = 1.0, rh_step = 5.0;
        bool seed_compatible = false, json = false;
    };
    auto so = std::make_shared<SweepOpts>();
    auto* sweep = cmd->add_subcommand("sweep", "Fig. S22: 2 h at 30-50 °C x 5-100 % RH, coupled vs dt-only, table and heat maps");
    sweep->add_option("--mrt", so->mrt, "'air' (full shade, MRT = air) or a temperature in °C (e.g. 55)")->capture_default_str();
    sweep->add_option("--t-step", so->t_step, "Air temperature step, °C")->capture_default_str();
    sweep->add_option("--rh-step", so->rh_step, "RH step, %")->capture_default_str();
    sweep->add_option("--out", so->out, "Folder for sweep.csv and the heat-map SVGs")->capture_default_str();
    sweep->add_flag("--seed-compatible", so->seed_compatible, "Reproduce the published code");
    sweep->add_flag("--json", so->json, "Print a JSON summary");
    sweep->callback([so] {
        if (so->t_step <= 0 || so->rh_step <= 0) throw UserError("--t-step and --rh-step must be positive");
        const bool mrt_air = so->mrt == "air";
        double mrt_c = 0.0;
        if (!mrt_air) {
            try {
                mrt_c = std::stod(so->mrt);
            } catch (const std::exception&) {
                throw UserError(fmt::format("--mrt '{}': expected 'air' or a temperature in °C", so->mrt));
            }
        }
        std::vector<std::pair<double, double>> grid;
        for (double t = 30.0; t <= 50.0 + 1e-9; t += so->t_step)
            for (double rh = 5.0; rh <= 100.0 + 1e-9; rh += so->rh_step) grid.emplace_back(t, rh);
        struct Cell {
            double core_dt = 0, skin_dt = 0, core_c = 0, skin_c = 0;
        };
        std::vector<Cell> cells(grid.size());
        const auto t0 = std::chrono::steady_clock::now();
        auto worker = [&](std::size_t begin) {
            for (std::size_t i = begin; i < grid.size(); i += 2) {
                tr::Exposure e;
                e.air_temp_c = grid[i].first;
                e.rh_pct = grid[i].second;
                e.mrt_c = mrt_air ? grid[i].first : mrt_c;
                const auto c = tr::simulate(e, {tr::ConvectionModel::coupled, so->seed_compatible});
                const auto d = tr::simulate(e, {tr::ConvectionModel::dt_only, so->seed_compatible});
                cells[i] = {d.final.core_temp_c, d.final.mean_skin_temp_c, c.final.core_temp_c, c.final.mean_skin_temp_c};
            }
        };
        auto other = std::async(std::launch::async, worker, 1);  // two cores
        worker(0);
        other.get();
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::filesystem::create_directories(so->out);
        std::ostringstream csv;
        csv << "air_temp_c,rh_pct,mrt_c,core_dt_only_c,skin_dt_only_c,core_coupled_c,skin_coupled_c,core_diff_c,skin_diff_c\n";
        double max_core = -1e9, min_core = 1e9;
        for (std::size_t i = 0; i < grid.size(); ++i) {
            const auto& c = cells[i];
            csv << fmt::format("{},{},{},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f}\n", grid[i].first, grid[i].second,
                               mrt_air ? grid[i].first : mrt_c, c.core_dt, c.skin_dt, c.core_c, c.skin_c, c.core_c - c.core_dt,
                               c.skin_c - c.skin_dt);
            max_core = std::max(max_core, c.core_c - c.core_dt);
            min_core = std::min(min_core, c.core_c - c.core_dt);
        }
        write_text((std::filesystem::path(so->out) / "sweep.csv").string(), csv.str());
        // Heat maps of the differences (coupled - dt-only), like Fig. S22's third column; `grid`
        // runs RH fastest, the layout the heat map takes.
        std::vector<double> air_temps_c, rhs_pct, core_diff_c, skin_diff_c;
        for (const auto& [t, rh] : grid) {
            if (air_temps_c.empty() || air_temps_c.back() != t) air_temps_c.push_back(t);
            if (air_temps_c.size() == 1) rhs_pct.push_back(rh);
        }
        for (const auto& c : cells) {
            core_diff_c.push_back(c.core_c - c.core_dt);
            skin_diff_c.push_back(c.skin_c - c.skin_dt);
        }
        const std::filesystem::path out(so->out);
        write_text((out / "core_diff.svg").string(), sweep_map_svg(air_temps_c, rhs_pct, core_diff_c, "Core", so->mrt));
        write_text((out / "skin_diff.svg").string(), sweep_map_svg(air_temps_c, rhs_pct, skin_diff_c, "Mean skin", so->mrt));
        if (so->json) {
            std::printf("%s\n", nlohmann::json{{"points", grid.size()}, {"seconds", seconds}, {"out", so->out},
                                               {"max_core_diff_c", max_core}, {"min_core_diff_c", min_core}}
                                    .dump(2)
                                    .c_str());
        } else {
            std::printf("S22 sweep, MRT %s: %zu conditions x 2 models x 2 h in %.2f s (two cores)\n", so->mrt.c_str(), grid.size(), seconds);
            std::printf("core difference (coupled - dt-only): %.2f .. %.2f °C\nwrote %s/sweep.csv, core_diff.svg, skin_diff.svg\n",
                        min_core, max_core, so->out.c_str());
        }
    });

    // ---- S23: air speed, constant and square wave ----
    auto speeds_seed = std::make_shared<bool>(false);
    auto speeds_json = std::make_shared<bool>(false);
    auto* speeds = cmd->add_subcommand("speeds", "Fig. S23: Fig. 4 conditions at air speeds 0-0.3 m/s, constant and 1-min square wave");
    speeds->add_flag("--seed-compatible", *speeds_seed, "Reproduce the published code");
    speeds->add_flag("--json", *speeds_json, "Print JSON");
    speeds->callback([speeds_seed, speeds_json] {
        nlohmann::json rows = nlohmann::json::array();
        if (!*speeds_json) std::printf("speed m/s   mode      core coupled  core dt-only  diff   skin coupled  skin dt-only  diff\n");
        for (double v : {0.0, 0.01, 0.02, 0.03, 0.05, 0.1, 0.15, 0.2, 0.3})
            for (double period : {0.0, 60.0}) {
                if (v == 0.0 && period > 0.0) continue;
                tr::Exposure e;
                e.air_speed = {v, period};
                const auto c = tr::simulate(e, {tr::ConvectionModel::coupled, *speeds_seed});
                const auto d = tr::simulate(e, {tr::ConvectionModel::dt_only, *speeds_seed});
                const char* mode = period > 0.0 ? "square" : "constant";
                rows.push_back({{"air_speed_m_s", v}, {"mode", mode}, {"core_coupled_c", c.final.core_temp_c},
                                {"core_dt_only_c", d.final.core_temp_c}, {"skin_coupled_c", c.final.mean_skin_temp_c},
                                {"skin_dt_only_c", d.final.mean_skin_temp_c}});
                if (!*speeds_json)
                    std::printf("  %5.2f    %-8s   %8.2f     %8.2f    %5.2f    %8.2f     %8.2f    %5.2f\n", v, mode, c.final.core_temp_c,
                                d.final.core_temp_c, c.final.core_temp_c - d.final.core_temp_c, c.final.mean_skin_temp_c,
                                d.final.mean_skin_temp_c, c.final.mean_skin_temp_c - d.final.mean_skin_temp_c);
            }
        if (*speeds_json) std::printf("%s\n", nlohmann::json{{"rows", rows}}.dump(2).c_str());
    });
}

}  // namespace manikind::cli
