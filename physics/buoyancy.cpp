#include "physics/buoyancy.hpp"

#include <cmath>

#include "physics/air_properties.hpp"
#include "physics/constants.hpp"
#include "physics/psychrometrics.hpp"
#include "physics/range_check.hpp"

namespace manikind::physics {

BuoyancyResult buoyancy(const SkinAirState& s) {
    require_in_range("skin wettedness", s.skin_wettedness, 0.0, 1.0, "");
    require_in_range("characteristic length", s.characteristic_length_m, 1e-3, 100.0, "m");
    BuoyancyResult r;
    const double p_air_pa = vapour_pressure_pa(s.air_temp_c, s.air_rh_pct);
    // A partially wet surface holds a vapour pressure between the air's and saturation.
    const double p_skin_pa =
        p_air_pa + s.skin_wettedness * (saturation_vapour_pressure_pa(s.skin_temp_c) - p_air_pa);
    r.dt_c = s.skin_temp_c - s.air_temp_c;
    // Limitations: partial wettedness scales the humidity term linearly, dT + 146 omega dC,
    // with dC = C_sk,sat - C_air; a dry skin has no compositional buoyancy at all.
    r.dc_kg_m3 = s.skin_wettedness * (saturation_concentration_kg_m3(s.skin_temp_c) -
                                      vapour_concentration_kg_m3(p_air_pa, s.air_temp_c));
    r.film_temp_c = 0.5 * (s.skin_temp_c + s.air_temp_c);
    r.film_density_kg_m3 =
        moist_air_density_kg_m3(r.film_temp_c, 0.5 * (p_skin_pa + p_air_pa), s.total_pressure_pa);
    r.beta_t_1_k = thermal_expansion_1_k(r.film_temp_c);
    r.beta_c_m3_kg = compositional_expansion_m3_kg(r.film_density_kg_m3);
    r.b_dt_n_m3 = gravity_m_s2 * r.film_density_kg_m3 * r.beta_t_1_k * r.dt_c;
    r.b_dc_n_m3 = gravity_m_s2 * r.film_density_kg_m3 * r.beta_c_m3_kg * r.dc_kg_m3;
    r.b_net_n_m3 = r.b_dt_n_m3 + r.b_dc_n_m3;

    const auto props = air_properties(r.film_temp_c);
    r.warnings = props.warnings;
    const AirProperties& p = props.properties;
    const double l3 = std::pow(s.characteristic_length_m, 3.0);
    // Eq. 2
    r.ra_dt = gravity_m_s2 * r.beta_t_1_k * r.dt_c * l3 /
              (p.kinematic_viscosity_m2_s * p.thermal_diffusivity_m2_s);
    r.ra_dc = gravity_m_s2 * r.beta_c_m3_kg * r.dc_kg_m3 * l3 /
              (p.kinematic_viscosity_m2_s * p.vapour_diffusivity_m2_s);
    r.ra_total = r.ra_dt + r.ra_dc;
    // Eq. 6-7: Ra_T is proportional to dT + (beta_C alpha / beta_T D) dC.
    r.coupling_coefficient = r.beta_c_m3_kg * p.thermal_diffusivity_m2_s /
                             (r.beta_t_1_k * p.vapour_diffusivity_m2_s);
    return r;
}

double coupling_coefficient(const SkinAirState& state) { return buoyancy(state).coupling_coefficient; }

std::optional<double> stagnation_air_temp_c(double rh_pct, double skin_temp_c, double skin_wettedness) {
    require_in_range("relative humidity", rh_pct, 0.0, 100.0, "%");
    auto net = [&](double air_temp_c) {
        SkinAirState s;
        s.skin_temp_c = skin_temp_c;
        s.air_temp_c = air_temp_c;
        s.air_rh_pct = rh_pct;
        s.skin_wettedness = skin_wettedness;
        return buoyancy(s).b_net_n_m3;
    };
    // Just above the skin temperature the humidity buoyancy wins (B_net > 0); far above it the
    // thermal buoyancy wins. Bisect for the crossing.
    double lo = skin_temp_c + 1e-6;
    double hi = skin_temp_c + 40.0;
    if (!(net(lo) > 0.0) || !(net(hi) < 0.0)) return std::nullopt;
    for (int i = 0; i < 100 && hi - lo > 1e-9; ++i) {
        const double mid = 0.5 * (lo + hi);
        (net(mid) > 0.0 ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}

}  // namespace manikind::physics
