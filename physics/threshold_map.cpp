#include "physics/threshold_map.hpp"

#include <cmath>
#include <limits>

#include "physics/buoyancy.hpp"
#include "physics/convection.hpp"

namespace manikind::physics {

ThresholdPoint threshold_point(double air_temp_c, double air_rh_pct, double skin_temp_c,
                               double mix_to_forced_ratio, FreeConvectionLaw law) {
    SkinAirState state;
    state.skin_temp_c = skin_temp_c;
    state.air_temp_c = air_temp_c;
    state.air_rh_pct = air_rh_pct;
    const BuoyancyResult b = buoyancy(state);
    ThresholdPoint p;
    p.air_temp_c = air_temp_c;
    p.air_rh_pct = air_rh_pct;
    p.h_free_w_m2k = law == FreeConvectionLaw::eq8 ? h_eq8_w_m2k(b.dt_c, b.dc_kg_m3) : h_dt_only_w_m2k(b.dt_c);
    p.speed_m_s = threshold_air_speed_m_s(p.h_free_w_m2k, mix_to_forced_ratio);
    return p;
}

ThresholdPoint minimum_threshold_on_grid(const ThresholdGrid& g) {
    ThresholdPoint best;
    best.speed_m_s = std::numeric_limits<double>::infinity();
    const int n_t = static_cast<int>(std::floor((g.air_temp_max_c - g.air_temp_min_c) / g.air_temp_step_c + 1e-9));
    const int n_rh = static_cast<int>(std::floor((g.rh_max_pct - g.rh_min_pct) / g.rh_step_pct + 1e-9));
    for (int i = 0; i <= n_t; ++i) {
        const double t_c = g.air_temp_min_c + i * g.air_temp_step_c;
        for (int j = 0; j <= n_rh; ++j) {
            const double rh = g.rh_min_pct + j * g.rh_step_pct;
            SkinAirState s;
            s.skin_temp_c = g.skin_temp_c;
            s.air_temp_c = t_c;
            s.air_rh_pct = rh;
            if (buoyancy(s).dc_kg_m3 <= 0.0) continue;
            const ThresholdPoint p = threshold_point(t_c, rh, g.skin_temp_c, g.mix_to_forced_ratio, g.law);
            if (p.speed_m_s < best.speed_m_s) best = p;
        }
    }
    return best;
}

}  // namespace manikind::physics
