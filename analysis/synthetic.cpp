#include "analysis/synthetic.hpp"

#include <cmath>
#include <random>

#include <fmt/core.h>

namespace manikind::analysis {

TrialData make_synthetic_trial(const ZoneMap& map, const SyntheticTrialOptions& o) {
    std::mt19937 rng(o.seed);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    TrialData d;
    const auto rows = static_cast<std::size_t>(std::floor(o.duration_s / o.sample_interval_s + 1e-9)) + 1;
    d.skin_temp_c.assign(map.size(), std::vector<double>(rows));
    d.heat_flux_w_m2.assign(map.size(), std::vector<double>(rows));
    d.t_s.resize(rows);
    d.air_temp_c.resize(rows);
    d.air_rh_pct.resize(rows);
    if (o.with_air_speed) d.air_speed_m_s.resize(rows);
    if (o.with_wall_temp) d.wall_temp_c.resize(rows);
    for (std::size_t i = 0; i < rows; ++i) {
        const double t = static_cast<double>(i) * o.sample_interval_s;
        const double decay = std::exp(-t / o.skin_time_constant_s);
        d.t_s[i] = t;
        d.air_temp_c[i] = o.air_temp_c + 0.05 * unit(rng);
        d.air_rh_pct[i] = o.air_rh_pct + 0.2 * unit(rng);
        if (o.with_air_speed) d.air_speed_m_s[i] = o.air_speed_m_s * (1.0 + 0.2 * unit(rng));
        if (o.with_wall_temp) d.wall_temp_c[i] = o.wall_temp_c + 0.05 * unit(rng);
        for (std::size_t z = 0; z < map.size(); ++z) {
            const double q = o.zone_flux_w_m2.empty() ? o.flux_w_m2 : o.zone_flux_w_m2[z];
            d.skin_temp_c[z][i] = o.skin_temp_c + o.skin_start_offset_c * decay + o.skin_noise_c * unit(rng);
            d.heat_flux_w_m2[z][i] = q + o.flux_start_offset_w_m2 * decay + o.flux_noise_w_m2 * unit(rng);
        }
    }
    return d;
}

Campaign make_synthetic_campaign(int cases, int replicates, const SyntheticTrialOptions& base) {
    Campaign c;
    c.name = fmt::format("synthetic-{}x{}", cases, replicates);
    c.zone_map = andi35_zone_map();
    c.instruments = default_instrument_specs();
    for (int k = 1; k <= cases; ++k) {
        for (int r = 1; r <= replicates; ++r) {
            SyntheticTrialOptions o = base;
            o.seed = base.seed + static_cast<unsigned>(k * 100 + r);
            // Cycles every 60 cases so any campaign size stays inside the reader's air range.
            o.air_temp_c = 35.0 + 0.5 * ((k - 1) % 60 + 1);
            o.zone_flux_w_m2.clear();
            for (const auto& z : c.zone_map.zones)
                o.zone_flux_w_m2.push_back(-2.0 * k + 0.3 * z.zone + 0.4 * (r - 2));
            Trial t;
            t.info.id = fmt::format("c{:02}-r{}", k, r);
            t.info.case_id = k;
            t.info.replicate = r;
            t.info.file = "trials/" + t.info.id + ".csv";
            t.info.skin_setpoint_c = o.skin_temp_c;
            t.info.wettedness = 1.0;
            t.data = make_synthetic_trial(c.zone_map, o);
            c.trials.push_back(std::move(t));
        }
    }
    return c;
}

}  // namespace manikind::analysis
