// `manikin simulate-campaign`: recordings from the simulated world, with hidden physics.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "analysis/recording.hpp"
#include "cli/commands.hpp"
#include "cli/simulated_campaign.hpp"
#include "base/user_error.hpp"
#include "sim/campaign/campaign_generator.hpp"

namespace manikind::cli {
namespace {

// Case list CSV with the columns of Table S3 (extra columns ignored):
// case,t_chamber_set_c,rh_chamber_set_pct,t_air_c,rh_air_pct,t_skin_c,skin_wettedness
std::vector<sim::CampaignCase> read_cases(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw UserError(fmt::format("{}: cannot open the case list", path));
    std::string line;
    std::getline(in, line);
    std::vector<std::string> header;
    {
        std::stringstream ss(line);
        std::string cell;
        while (std::getline(ss, cell, ',')) header.push_back(cell);
    }
    const std::vector<std::string> needed = {"case", "t_chamber_set_c", "rh_chamber_set_pct", "t_air_c",
                                             "rh_air_pct", "t_skin_c", "skin_wettedness"};
    std::vector<std::size_t> col;
    for (const auto& n : needed) {
        const auto it = std::find(header.begin(), header.end(), n);
        if (it == header.end()) throw UserError(fmt::format("{}:1: missing column '{}' (expected the columns of Table S3)", path, n));
        col.push_back(static_cast<std::size_t>(it - header.begin()));
    }
    std::vector<sim::CampaignCase> cases;
    for (int line_no = 2; std::getline(in, line); ++line_no) {
        if (line.empty()) continue;
        std::vector<std::string> cells;
        std::stringstream ss(line);
        std::string cell;
        while (std::getline(ss, cell, ',')) cells.push_back(cell);
        auto num = [&](std::size_t i) {
            const std::size_t c = col[i];
            if (c >= cells.size()) throw UserError(fmt::format("{}:{}: column '{}' is missing", path, line_no, needed[i]));
            char* end = nullptr;
            const double v = std::strtod(cells[c].c_str(), &end);
            if (cells[c].empty() || *end != '\0')
                throw UserError(fmt::format("{}:{}:{} ({}): expected a number, found '{}'", path, line_no, c + 1, needed[i], cells[c]));
            return v;
        };
        sim::CampaignCase k;
        k.case_id = static_cast<int>(num(0));
        k.chamber_temp_c = num(1);
        k.chamber_rh_pct = num(2);
        k.air_temp_c = num(3);
        k.air_rh_pct = num(4);
        k.skin_setpoint_c = num(5);
        k.wettedness = num(6);
        if (k.air_rh_pct < 0 || k.air_rh_pct > 100 || k.wettedness < 0 || k.wettedness > 1)
            throw UserError(fmt::format("{}:{}: RH must be 0-100 % and wettedness 0-1", path, line_no));
        cases.push_back(k);
    }
    if (cases.empty()) throw UserError(fmt::format("{}: no cases", path));
    return cases;
}

}  // namespace

void add_simulate_command(CLI::App& app) {
    struct Opts {
        std::string cases_file, out;
        std::vector<std::string> effects;
        int replicates = 3;
        std::uint64_t seed = 1;
        double unsteady = 0.0;
        bool json = false;
        sim::ReplicateScatter scatter;
        bool no_scatter = false;
        bool chamber_by_probes = false;
        double probe_air_bias_c = 0.0, probe_rh_bias_pct = 0.0, probe_wall_bias_c = 0.0;
        double flux_gain = 0.0, flux_offset_w_m2 = 0.0;
    };
    auto o = std::make_shared<Opts>();
    auto* cmd = app.add_subcommand("simulate-campaign",
                                   "Write a recorded campaign (manikin-recording/1) from the simulated world, with hidden physics");
    cmd->add_option("--out", o->out, "Output folder (campaign.json + trials/*.csv)")->required();
    cmd->add_option("--cases", o->cases_file, "Case list CSV with Table S3's columns (default: the paper's 15 cases)");
    cmd->add_option("--effect", o->effects,
                    "Hidden physics in the world, repeatable: term:param=value[:region=R][:zones=5,23]\n"
                    "terms: humidity_buoyancy:gamma, diffusion_floor:h0, mixed_convection:scale, wall_offset:delta_c,\n"
                    "air_temp_bias:bias_c, textile_resistance:r_m2k_w, partial_wettedness:fraction:region=,\n"
                    "heat_leak:q_w_m2:zones=");
    cmd->add_option("--replicates", o->replicates, "Trials per case")->capture_default_str();
    cmd->add_option("--seed", o->seed, "Random seed (same seed, same recordings)")->capture_default_str();
    cmd->add_option("--unsteady-probability", o->unsteady, "Chance that a trial never settles (0-1)")->capture_default_str();
    // Replicate-to-replicate scatter, drawn once per trial (1 sigma each).
    sim::ReplicateScatter& sc = o->scatter;
    const std::vector<CLI::Option*> spreads = {
        cmd->add_option("--replicate-flux-rel-sd", sc.replicate_flux_rel_sd,
                        "Relative zone-flux scatter between replicates: flux x (1 + e), e ~ N(0, this) per trial and zone")
            ->capture_default_str(),
        cmd->add_option("--replicate-flux-sd", sc.replicate_flux_sd_w_m2,
                        "Absolute zone-flux offset between replicates, W/m2, per trial and zone")
            ->capture_default_str(),
        cmd->add_option("--replicate-air-sd", sc.replicate_air_sd_c,
                        "Enclosure air temperature actually reached minus the case's nominal, deg C, per trial (the physics follows it)")
            ->capture_default_str(),
        cmd->add_option("--replicate-rh-sd", sc.replicate_rh_sd_pct,
                        "Enclosure RH actually reached minus the case's nominal, % RH, per trial (the physics follows it)")
            ->capture_default_str(),
        cmd->add_option("--replicate-wall-sd", sc.replicate_wall_sd_c,
                        "Wall temperature off its usual offset below the air, deg C, per trial")
            ->capture_default_str(),
        cmd->add_option("--probe-air-sd", sc.probe_air_sd_c,
                        "Recorded minus actual air temperature, deg C, constant within a trial")
            ->capture_default_str(),
        cmd->add_option("--probe-rh-sd", sc.probe_rh_sd_pct, "Recorded minus actual RH, % RH, constant within a trial")
            ->capture_default_str(),
        cmd->add_option("--probe-wall-sd", sc.probe_wall_sd_c,
                        "Recorded minus actual wall temperature, deg C, constant within a trial")
            ->capture_default_str()};
    auto* no_scatter = cmd->add_flag("--no-scatter", o->no_scatter,
                                     "No replicate scatter at all (every option above 0): replicates differ by sensor noise only");
    for (auto* spread : spreads) no_scatter->excludes(spread);
    // A real lab's instruments are off by a fixed calibration error (the same in every trial).
    cmd->add_option("--probe-air-bias", o->probe_air_bias_c, "Air probe's calibration error, deg C (recorded minus actual), every trial")
        ->capture_default_str();
    cmd->add_option("--probe-rh-bias", o->probe_rh_bias_pct, "RH probe's calibration error, % RH, every trial")->capture_default_str();
    cmd->add_option("--probe-wall-bias", o->probe_wall_bias_c, "Wall thermocouple's calibration error, deg C, every trial")
        ->capture_default_str();
    cmd->add_flag("--chamber-by-probes", o->chamber_by_probes,
                  "The lab trims its chamber until its own probes read each case's air temperature and humidity, so the "
                  "enclosure really settles off them by --probe-air-bias and --probe-rh-bias (default: it settles at the "
                  "case's values and only the recordings are off)");
    cmd->add_option("--flux-gain", o->flux_gain, "Manikin heat-flux calibration gain: recorded = (1 + this) q + offset")
        ->capture_default_str();
    cmd->add_option("--flux-offset", o->flux_offset_w_m2, "Manikin heat-flux calibration offset, W/m2")->capture_default_str();
    cmd->add_flag("--json", o->json, "Print a JSON summary");
    cmd->footer("Example: manikin simulate-campaign --effect humidity_buoyancy:gamma=146 --out /tmp/c146\n"
                "then:    manikin analyze /tmp/c146 ; manikin reconcile /tmp/c146");
    cmd->callback([o] {
        sim::GeneratorOptions g;
        g.replicates = o->replicates;
        g.seed = o->seed;
        g.unsteady_probability = o->unsteady;
        g.scatter = o->no_scatter ? sim::ReplicateScatter::none() : o->scatter;
        g.probe_air_bias_c = o->probe_air_bias_c;
        g.probe_rh_bias_pct = o->probe_rh_bias_pct;
        g.probe_wall_bias_c = o->probe_wall_bias_c;
        g.chamber_set_by_probes = o->chamber_by_probes;
        g.flux_calibration_gain = o->flux_gain;
        g.flux_calibration_offset_w_m2 = o->flux_offset_w_m2;
        g.world.name = "world";
        try {
            for (const auto& e : o->effects) g.world.terms.push_back(sim::parse_effect(e));
        } catch (const std::invalid_argument& e) {
            throw UserError(e.what());
        }
        const auto cases = o->cases_file.empty() ? sim::table_s3_cases() : read_cases(o->cases_file);
        const auto t0 = std::chrono::steady_clock::now();
        int unsteady = 0;
        analysis::Campaign c;
        try {
            c = simulate_campaign(std::filesystem::path(o->out).filename().string(), cases, g, &unsteady);
        } catch (const std::invalid_argument& e) {
            throw UserError(e.what());
        }
        analysis::write_campaign(o->out, c);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (o->json) {
            std::printf("%s\n", nlohmann::json{{"out", o->out}, {"trials", c.trials.size()}, {"cases", cases.size()},
                                               {"effects", o->effects}, {"seed", o->seed}, {"seconds", seconds},
                                               {"scatter", {{"replicate_flux_rel_sd", g.scatter.replicate_flux_rel_sd},
                                                            {"replicate_flux_sd_w_m2", g.scatter.replicate_flux_sd_w_m2},
                                                            {"replicate_air_sd_c", g.scatter.replicate_air_sd_c},
                                                            {"replicate_rh_sd_pct", g.scatter.replicate_rh_sd_pct},
                                                            {"replicate_wall_sd_c", g.scatter.replicate_wall_sd_c},
                                                            {"probe_air_sd_c", g.scatter.probe_air_sd_c},
                                                            {"probe_rh_sd_pct", g.scatter.probe_rh_sd_pct},
                                                            {"probe_wall_sd_c", g.scatter.probe_wall_sd_c}}}}
                                    .dump(2)
                                    .c_str());
        } else {
            std::printf("wrote %zu trials (%zu cases x %d replicates, 75 min at 5 s, 35 zones) to %s in %.2f s\n",
                        c.trials.size(), cases.size(), o->replicates, o->out.c_str(), seconds);
            std::printf("hidden physics: %s\n", o->effects.empty() ? "none (the baseline twin)" : fmt::format("{}", fmt::join(o->effects, ", ")).c_str());
            if (unsteady > 0) std::printf("%d trial(s) were generated never to settle\n", unsteady);
        }
        spdlog::debug("seed {}", o->seed);
    });
}

}  // namespace manikind::cli
