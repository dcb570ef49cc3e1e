#include "physics/psychrometrics.hpp"

#include <cmath>

#include "physics/constants.hpp"
#include "physics/range_check.hpp"

namespace manikind::physics {

double saturation_vapour_pressure_pa(double temp_c) {
    require_in_range("temperature", temp_c, -40.0, 200.0, "degC");
    const double t_k = temp_c + kelvin_offset;
    // Seed code / docs/twin-baseline.md step 1: exp(77.3450 + 0.0057 T - 7235/T) / T^8.2, T in K.
    return std::exp(77.3450 + 0.0057 * t_k - 7235.0 / t_k) / std::pow(t_k, 8.2);
}

double saturation_vapour_pressure_iapws_pa(double temp_c) {
    require_in_range("temperature", temp_c, 0.0, 200.0, "degC");
    // ln(p/pc) = (Tc/T)(a1 t + a2 t^1.5 + a3 t^3 + a4 t^3.5 + a5 t^4 + a6 t^7.5), t = 1 - T/Tc.
    constexpr double tc_k = 647.096, pc_pa = 22.064e6;
    constexpr double a1 = -7.85951783, a2 = 1.84408259, a3 = -11.7866497, a4 = 22.6807411, a5 = -15.9618719, a6 = 1.80122502;
    const double t_k = temp_c + kelvin_offset;
    const double t = 1.0 - t_k / tc_k;
    const double sum = a1 * t + a2 * std::pow(t, 1.5) + a3 * t * t * t + a4 * std::pow(t, 3.5) + a5 * t * t * t * t +
                       a6 * std::pow(t, 7.5);
    return pc_pa * std::exp(tc_k / t_k * sum);
}

double vapour_pressure_pa(double temp_c, double rh_pct) {
    require_in_range("relative humidity", rh_pct, 0.0, 100.0, "%");
    return rh_pct / 100.0 * saturation_vapour_pressure_pa(temp_c);
}

double vapour_concentration_kg_m3(double vapour_pressure_pa, double temp_c) {
    // Eq. 1 text: p = C R (T + 273.15) / M_w, so C = p M_w / (R T). The offset is applied once
    // (the seed code applies it twice to a temperature already in kelvin; see docs).
    return vapour_pressure_pa * molar_mass_water_kg_mol /
           (gas_constant_j_mol_k * (temp_c + kelvin_offset));
}

double saturation_concentration_kg_m3(double temp_c) {
    return vapour_concentration_kg_m3(saturation_vapour_pressure_pa(temp_c), temp_c);
}

double moist_air_density_kg_m3(double temp_c, double vapour_pressure_pa, double total_pressure_pa) {
    // Ideal mixture: rho = ((p - p_v) M_a + p_v M_w) / (R T).
    const double t_k = temp_c + kelvin_offset;
    return ((total_pressure_pa - vapour_pressure_pa) * molar_mass_dry_air_kg_mol +
            vapour_pressure_pa * molar_mass_water_kg_mol) /
           (gas_constant_j_mol_k * t_k);
}

double humidity_ratio_kg_kg(double vapour_pressure_pa, double total_pressure_pa) {
    const double ratio = molar_mass_water_kg_mol / molar_mass_dry_air_kg_mol;  // 0.622
    return ratio * vapour_pressure_pa / (total_pressure_pa - vapour_pressure_pa);
}

double relative_humidity_from_ratio_pct(double temp_c, double humidity_ratio_kg_kg,
                                        double total_pressure_pa) {
    const double ratio = molar_mass_water_kg_mol / molar_mass_dry_air_kg_mol;
    const double p_v = humidity_ratio_kg_kg * total_pressure_pa / (ratio + humidity_ratio_kg_kg);
    return 100.0 * p_v / saturation_vapour_pressure_pa(temp_c);
}

}  // namespace manikind::physics
