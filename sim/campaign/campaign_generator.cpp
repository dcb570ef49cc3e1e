#include "sim/campaign/campaign_generator.hpp"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <random>
#include <sstream>
#include <stdexcept>

#include <fmt/chrono.h>
#include <fmt/core.h>

namespace manikind::sim {
namespace tw = physics::twin;
namespace {

// Sensors report at a finite resolution; recordings carry no more digits than that.
// Dividing the rounded integer by a power of ten gives the double nearest the decimal, which
// the writer then prints with no more digits than the sensor has.
double at_resolution(double value, int decimals) {
    const double scale = std::pow(10.0, decimals);
    return std::round(value * scale) / scale;
}

}  // namespace

std::vector<CampaignCase> table_s3_cases() {
    // case, T_c, RH_c, T_air, RH_air, T_sk, wettedness (Table S3)
    return {{1, 40, 24.6, 40.4, 27.6, 34.0, 0}, {2, 42, 22.2, 42.0, 25.4, 34.0, 0}, {3, 44, 20, 44.2, 23.5, 34.0, 0},
            {4, 44, 20, 43.8, 23.8, 31.0, 0},   {5, 35, 27, 35.3, 35.6, 35.0, 1},   {6, 35, 44, 35.3, 48.7, 35.0, 1},
            {7, 35, 60, 35.5, 65.2, 35.4, 1},   {8, 35, 80, 35.5, 81.4, 35.4, 1},   {9, 40, 19, 39.6, 38.3, 35.0, 1},
            {10, 40, 34, 39.6, 48.3, 35.0, 1},  {11, 40, 45, 39.5, 60.3, 35.0, 1},  {12, 40, 61, 39.6, 68.9, 35.0, 1},
            {13, 44, 22, 42.4, 34.7, 35.0, 1},  {14, 44, 34, 42.5, 47.1, 35.0, 1},  {15, 44, 49, 42.4, 59.4, 35.0, 1}};
}

std::vector<GeneratedTrial> generate_campaign(const std::vector<CampaignCase>& cases, const std::vector<ZoneSpec>& zones,
                                              const GeneratorOptions& o) {
    if (o.replicates < 1) throw std::invalid_argument("replicates must be at least 1");
    if (!(o.sample_period_s > 0.0) || !(o.duration_s >= o.sample_period_s))
        throw std::invalid_argument("sample period must be positive and no longer than the trial");
    if (o.unsteady_probability < 0.0 || o.unsteady_probability > 1.0)
        throw std::invalid_argument("unsteady probability must be within 0..1");
    if (zones.empty()) throw std::invalid_argument("no zones");
    o.scatter.validate();
    if (!(std::abs(o.flux_calibration_gain) < 0.5) || !std::isfinite(o.flux_calibration_offset_w_m2))
        throw std::invalid_argument("the flux calibration gain must be within +-0.5 and its offset finite");
    for (const double bias : {o.probe_air_bias_c, o.probe_rh_bias_pct, o.probe_wall_bias_c, o.flux_calibration_offset_w_m2 / 10.0})
        if (!std::isfinite(bias) || std::abs(bias) > 20.0) throw std::invalid_argument("probe calibration errors must be finite and within 20");
    const ReplicateScatter& sc = o.scatter;
    std::mt19937_64 rng(o.seed);
    std::normal_distribution<double> gauss(0.0, 1.0);
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    const auto n_samples = static_cast<std::size_t>(std::floor(o.duration_s / o.sample_period_s)) + 1;

    std::vector<GeneratedTrial> trials;
    int trial_index = 0;
    for (const CampaignCase& c : cases) {
        for (int r = 1; r <= o.replicates; ++r, ++trial_index) {
            GeneratedTrial t;
            t.id = fmt::format("c{:02d}-r{}", c.case_id, r);
            t.case_id = c.case_id;
            t.replicate = r;
            t.conditions = c;
            // Trials run back to back, 2 h apart (75 min + set-up), from the campaign start.
            const std::time_t start = static_cast<std::time_t>(o.start_epoch_s + 7200 * trial_index);
            t.started_utc = fmt::format("{:%Y-%m-%dT%H:%M:%SZ}", fmt::gmtime(start));
            t.unsteady = uniform(rng) < o.unsteady_probability;
            // The enclosure's actual conditions this trial: the physics follows these.
            const double set_air_c = c.air_temp_c - (o.chamber_set_by_probes ? o.probe_air_bias_c : 0.0);
            const double set_rh_pct = c.air_rh_pct - (o.chamber_set_by_probes ? o.probe_rh_bias_pct : 0.0);
            const double air_c = set_air_c + sc.replicate_air_sd_c * gauss(rng);
            const double rh_pct = std::clamp(set_rh_pct + sc.replicate_rh_sd_pct * gauss(rng), 1.0, 99.0);
            const double wall_c = air_c - o.wall_below_air_c + sc.replicate_wall_sd_c * gauss(rng);
            std::vector<double> zone_offset_w_m2(zones.size());
            for (auto& z : zone_offset_w_m2) z = sc.replicate_flux_sd_w_m2 * gauss(rng);
            const std::size_t drifting_zone = static_cast<std::size_t>(uniform(rng) * static_cast<double>(zones.size())) % zones.size();
            // Every draw is taken even at zero spread, so the sensor noise that follows is the
            // same with and without scatter for a given seed.
            std::vector<double> zone_flux_factor(zones.size());
            for (auto& f : zone_flux_factor) f = 1.0 + sc.replicate_flux_rel_sd * gauss(rng);
            // The probes' per-trial errors: only the recorded channels carry them.
            const double probe_air_c = sc.probe_air_sd_c * gauss(rng) + o.probe_air_bias_c;
            const double probe_rh_pct = sc.probe_rh_sd_pct * gauss(rng) + o.probe_rh_bias_pct;
            const double probe_wall_c = sc.probe_wall_sd_c * gauss(rng) + o.probe_wall_bias_c;
            t.truth = {air_c, rh_pct, wall_c, probe_air_c, probe_rh_pct, probe_wall_c, zone_flux_factor, zone_offset_w_m2};

            t.skin_temp_c.assign(zones.size(), std::vector<double>(n_samples));
            t.heat_flux_w_m2.assign(zones.size(), std::vector<double>(n_samples));
            tw::TrialConditions cond;
            cond.wettedness = c.wettedness;
            for (const auto& z : zones) cond.zones.push_back(z.zone);
            for (std::size_t k = 0; k < n_samples; ++k) {
                const double time_s = static_cast<double>(k) * o.sample_period_s;
                t.t_s.push_back(time_s);
                // Air and walls: settled before the manikin starts, with sensor noise.
                const double a = air_c + probe_air_c + o.air_noise_c * gauss(rng);
                const double h = std::clamp(rh_pct + probe_rh_pct + o.rh_noise_pct * gauss(rng), 0.5, 99.5);
                const double v = std::max(0.0, o.air_speed_mean_m_s * (1.0 + 0.4 * gauss(rng)));
                t.air_temp_c.push_back(at_resolution(a, 2));          // EE181 via datalogger
                t.air_rh_pct.push_back(at_resolution(h, 1));
                t.air_speed_m_s.push_back(at_resolution(v, 3));      // sonic, mm/s
                t.wall_temp_c.push_back(at_resolution(wall_c + probe_wall_c + 0.02 * gauss(rng), 2));
                // The shell warms from the air temperature toward its setpoint (first-order lag).
                const double approach = std::exp(-time_s / o.skin_time_constant_s);
                cond.air_temp_c = air_c;
                cond.air_rh_pct = rh_pct;
                cond.wall_temp_c = wall_c;
                cond.air_speed_m_s = o.air_speed_mean_m_s;
                for (std::size_t z = 0; z < zones.size(); ++z) {
                    double skin_c = c.skin_setpoint_c - (c.skin_setpoint_c - air_c) * approach;
                    // An unsteady trial: one zone's controller hunts slowly and never settles.
                    if (t.unsteady && z == drifting_zone) skin_c += 0.15 * std::sin(2.0 * M_PI * time_s / 1500.0);
                    cond.zones[z].skin_temp_c = skin_c;
                }
                const auto fluxes = tw::predict(o.world, cond);
                for (std::size_t z = 0; z < zones.size(); ++z) {
                    // The heater also pays for warming the shell while it approaches the setpoint.
                    const double storage_w_m2 = 8000.0 * (c.skin_setpoint_c - air_c) * approach / o.skin_time_constant_s;
                    t.skin_temp_c[z][k] = at_resolution(cond.zones[z].skin_temp_c + o.skin_noise_c * gauss(rng), 3);
                    // The relative scatter scales what the physics loses (fit and wetting change the
                    // heat transfer itself); the shell's storage is the heater's and stays unscaled.
                    const double flux_w_m2 = fluxes[z].q_total_w_m2 * zone_flux_factor[z] + storage_w_m2 + zone_offset_w_m2[z];
                    t.heat_flux_w_m2[z][k] = at_resolution(flux_w_m2 * (1.0 + o.flux_calibration_gain) +
                                                               o.flux_calibration_offset_w_m2 + o.flux_noise_w_m2 * gauss(rng),
                                                           2);
                }
            }
            trials.push_back(std::move(t));
        }
    }
    return trials;
}

tw::Term parse_effect(const std::string& text) {
    auto fail = [&](const std::string& why) {
        return std::invalid_argument(fmt::format("--effect '{}': {}; expected term:param=value[,param=value]"
                                                 "[:region=R][:zones=5,23], e.g. humidity_buoyancy:gamma=146",
                                                 text, why));
    };
    std::vector<std::string> parts;
    std::stringstream ss(text);
    std::string part;
    while (std::getline(ss, part, ':')) parts.push_back(part);
    if (parts.empty() || parts[0].empty()) throw fail("no term name");
    tw::Term term;
    term.name = parts[0];
    for (std::size_t i = 1; i < parts.size(); ++i) {
        std::stringstream kv(parts[i]);
        std::string item;
        while (std::getline(kv, item, ',')) {
            const auto eq = item.find('=');
            if (eq == std::string::npos) {
                // continuation of a zones list: zones=5,23
                if (!term.zones.empty() && !item.empty() && item.find_first_not_of("0123456789") == std::string::npos) {
                    term.zones.push_back(std::stoi(item));
                    continue;
                }
                throw fail("'" + item + "' is not key=value");
            }
            const std::string key = item.substr(0, eq), value = item.substr(eq + 1);
            if (key == "region") {
                term.region = value;
            } else if (key == "zones") {
                if (value.empty() || value.find_first_not_of("0123456789") != std::string::npos) throw fail("zones must be numbers");
                term.zones.push_back(std::stoi(value));
            } else {
                char* end = nullptr;
                const double x = std::strtod(value.c_str(), &end);
                if (value.empty() || *end != '\0' || !std::isfinite(x)) throw fail("'" + value + "' is not a number");
                term.parameters[key] = x;
            }
        }
    }
    try {
        tw::validate_term(term);
    } catch (const std::invalid_argument& e) {
        throw fail(e.what());
    }
    return term;
}

}  // namespace manikind::sim
