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

#include "daemon/cli/commands.hpp"
#include "daemon/core/user_error.hpp"
#include "physics/sign_convention.hpp"
#include "physics/thermoreg/stolwijk.hpp"

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

// Fig. 4 as SVG: temperatures (top) and heat rates with 50 x (dT + 146 dC) (bottom).
std::string fig4_svg(const tr::SimulationResult& r, const std::string& title) {
    std::ostringstream o;
    const double w = 720, h = 640, left = 70, right = 20, panel_h = 240;
    const double t_max_min = r.series.back().t_s / 60.0;
    o << fmt::format(R"(<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" font-family="Helvetica,Arial,sans-serif" font-size="12">)", w, h)
      << fmt::format("\n<rect width=\"{}\" height=\"{}\" fill=\"white\"/>\n<text x=\"{}\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">{}</text>\n", w, h, w / 2, title);
    struct Line {
        std::string label, color;
        std::vector<double> y;
    };
    auto panel = [&](double top, double ylo, double yhi, const std::string& ylabel, const std::vector<Line>& lines) {
        const double pw = w - left - right;
        auto px = [&](double t_min) { return left + t_min / t_max_min * pw; };
        auto py = [&](double y) { return top + panel_h - (y - ylo) / (yhi - ylo) * panel_h; };
        o << fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"black\"/>\n", left, top, pw, panel_h);
        for (int i = 0; i <= 6; ++i) {
            const double tv = t_max_min * i / 6.0, yv = ylo + (yhi - ylo) * i / 6.0;
            o << fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{:.0f}</text>\n", px(tv), top + panel_h + 15, tv)
              << fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">{:.4g}</text>\n", left - 5, py(yv) + 4, yv);
        }
        o << fmt::format("<text x=\"16\" y=\"{}\" transform=\"rotate(-90 16 {})\" text-anchor=\"middle\">{}</text>\n",
                         top + panel_h / 2, top + panel_h / 2, ylabel);
        int row = 0;
        for (const auto& line : lines) {
            std::string pts;
            for (std::size_t i = 0; i < r.series.size(); ++i)
                pts += fmt::format("{:.1f},{:.1f} ", px(r.series[i].t_s / 60.0), py(std::clamp(line.y[i], ylo, yhi)));
            o << fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"2\" points=\"{}\"/>\n", line.color, pts)
              << fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" stroke-width=\"3\"/><text x=\"{}\" y=\"{}\">{}</text>\n",
                             left + 10, top + 14 + 15 * row, left + 30, top + 14 + 15 * row, line.color, left + 35, top + 18 + 15 * row, line.label);
            ++row;
        }
    };
    auto series = [&](auto f) {
        std::vector<double> v;
        for (const auto& s : r.series) v.push_back(f(s));
        return v;
    };
    panel(40, 34.0, 40.0, "Temperature (°C)",
          {{"core", "#d62728", series([](const auto& s) { return s.core_temp_c; })},
           {"mean skin", "#1f77b4", series([](const auto& s) { return s.mean_skin_temp_c; })}});
    panel(40 + panel_h + 50, -400.0, 400.0, "Heat rate (W), losses + = lost",
          {{"evaporation loss", "#1f77b4", series([](const auto& s) { return printed_rates(s).evaporation_loss_w; })},
           {"radiation loss", "#ff7f0e", series([](const auto& s) { return printed_rates(s).radiation_loss_w; })},
           {"convection loss", "#2ca02c", series([](const auto& s) { return printed_rates(s).convection_loss_w; })},
           {"metabolic production", "#9467bd", series([](const auto& s) { return printed_rates(s).metabolic_production_w; })},
           {"storage (+ = stored)", "#d62728", series([](const auto& s) { return printed_rates(s).storage_w; })},
           {"50 x (dT + 146 dC)", "#7f7f7f", series([](const auto& s) { return 50.0 * s.mean_buoyancy_drive_c; })}});
    o << fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">Time (min)</text>\n</svg>\n", left + (w - left - right) / 2, h - 8);
    return o.str();
}

void write_text(const std::string& path, const std::string& text) {
    std::ofstream f(path, std::ios::binary);
    f << text;
    if (!f) throw UserError(fmt::format("{}: cannot write", path));
}

struct RunOpts {
    tr::Exposure exposure;
    std::string duration = "2h", convection = "coupled", csv, plot;
    bool seed_compatible = false, json = false;
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
}

}  // namespace

void add_thermoreg_command(CLI::App& app) {
    auto o = std::make_shared<RunOpts>();
    auto* cmd = app.add_subcommand("thermoreg", "Human thermoregulation (the paper's Stolwijk model): Fig. 4, sweeps, air speed");
    add_exposure_options(cmd, *o);
    cmd->add_flag("--json", o->json, "Print the time series as JSON (FORMATS.md)");
    cmd->add_option("--csv", o->csv, "Write the time series as CSV");
    cmd->add_option("--plot", o->plot, "Write a Fig. 4-like SVG");
    cmd->footer("Defaults are Fig. 4: 41 °C, 20 % RH, MRT 55 °C, still air, 1.5 met, 0.25 clo, 2 h.\n"
                "Heat rates: " + rates_sign_text() + "\n(Fig. 4 plots the opposite sign). Core = trunk core.\n"
                "Examples:\n  manikin thermoreg --seed-compatible --plot fig4.svg\n"
                "  manikin thermoreg --convection dt-only --mrt 41 --json\n"
                "  manikin thermoreg sweep --mrt 55 --out s22/\n  manikin thermoreg speeds");
    cmd->callback([o, cmd] {
        if (!cmd->get_subcommands().empty()) return;  // a subcommand ran
        o->exposure.duration_s = parse_duration_s(o->duration);
        tr::ModelOptions m{parse_model(o->convection), o->seed_compatible};
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
        // Heat maps of the differences (coupled - dt-only), like Fig. S22's third column.
        for (const bool core : {true, false}) {
            std::ostringstream svg;
            const int nt = static_cast<int>(std::floor(20.0 / so->t_step + 1e-9)) + 1;
            const int nr = static_cast<int>(std::floor(95.0 / so->rh_step + 1e-9)) + 1;
            const double cw = 560.0 / nt, ch = 400.0 / nr;
            svg << R"(<svg xmlns="http://www.w3.org/2000/svg" width="720" height="500" font-family="Helvetica,Arial,sans-serif" font-size="12">)"
                << "<rect width=\"720\" height=\"500\" fill=\"white\"/>\n"
                << fmt::format("<text x=\"360\" y=\"22\" text-anchor=\"middle\" font-size=\"14\">{} difference, coupled - dt-only, after 2 h (MRT {})</text>\n",
                               core ? "Core" : "Mean skin", so->mrt);
            for (std::size_t i = 0; i < grid.size(); ++i) {
                const double d = core ? cells[i].core_c - cells[i].core_dt : cells[i].skin_c - cells[i].skin_dt;
                const double x = std::clamp(d / 1.5, -1.0, 1.0);  // ±1.5 °C full scale
                const int red = x > 0 ? 255 : static_cast<int>(255 * (1 + x)), blue = x < 0 ? 255 : static_cast<int>(255 * (1 - x));
                const int green = static_cast<int>(255 * (1 - std::abs(x)));
                const double px = 70 + std::round((grid[i].first - 30.0) / so->t_step) * cw;
                const double py = 440 - (std::round((grid[i].second - 5.0) / so->rh_step) + 1) * ch;
                svg << fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" fill=\"rgb({},{},{})\"><title>{} °C, {} %: {:+.2f} °C</title></rect>\n",
                                   px, py, cw + 0.5, ch + 0.5, red, green, blue, grid[i].first, grid[i].second, d);
            }
            for (int t = 30; t <= 50; t += 5)
                svg << fmt::format("<text x=\"{:.1f}\" y=\"458\" text-anchor=\"middle\">{}</text>\n", 70 + (t - 30) / so->t_step * cw + cw / 2, t);
            for (int rh = 5; rh <= 100; rh += 15)
                svg << fmt::format("<text x=\"64\" y=\"{:.1f}\" text-anchor=\"end\">{}</text>\n", 440 - ((rh - 5) / so->rh_step + 0.5) * ch + 4, rh);
            svg << "<text x=\"350\" y=\"480\" text-anchor=\"middle\">Air temperature (°C)</text>"
                << "<text x=\"20\" y=\"240\" transform=\"rotate(-90 20 240)\" text-anchor=\"middle\">RH (%)</text>"
                << "<text x=\"650\" y=\"60\">red: coupled hotter</text><text x=\"650\" y=\"76\">blue: cooler</text>"
                << "<text x=\"650\" y=\"92\">full scale ±1.5 °C</text>\n</svg>\n";
            write_text((std::filesystem::path(so->out) / (core ? "core_diff.svg" : "skin_diff.svg")).string(), svg.str());
        }
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
