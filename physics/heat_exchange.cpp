#include "physics/heat_exchange.hpp"

#include <cmath>

#include "physics/air_properties.hpp"
#include "physics/constants.hpp"
#include "physics/range_check.hpp"

namespace manikind::physics {

double evaporative_heat_flux_w_m2(double h_c_w_m2k, double skin_vapour_pressure_pa,
                                  double air_vapour_pressure_pa, double skin_wettedness,
                                  double lewis_relation) {
    require_in_range("skin wettedness", skin_wettedness, 0.0, 1.0, "");
    // Eq. 1: h_e = 16.5 h_c (W m^-2 kPa^-1), driving difference in kPa.
    return skin_wettedness * lewis_relation * h_c_w_m2k *
           (skin_vapour_pressure_pa - air_vapour_pressure_pa) / 1000.0;
}

double latent_heat_vaporisation_j_kg(double temp_c) {
    return 2.501e6 - 2361.0 * temp_c;  // Rogers & Yau linear fit, within 0.1 % over 0..60 °C
}

double lewis_relation_from_properties_k_kpa(double air_temp_c, double skin_temp_c,
                                            double total_pressure_pa) {
    const AirProperties p = air_properties(air_temp_c).properties;
    const double specific_heat_j_kg_k = 1006.0;  // dry air near 25 °C
    const double lewis_number = p.thermal_diffusivity_m2_s / p.vapour_diffusivity_m2_s;
    const double molar_ratio = molar_mass_water_kg_mol / molar_mass_dry_air_kg_mol;
    // Eq. S4, per Pa; x1000 for per kPa.
    const double lr_k_pa = latent_heat_vaporisation_j_kg(skin_temp_c) * molar_ratio /
                           (total_pressure_pa * specific_heat_j_kg_k * std::pow(lewis_number, 2.0 / 3.0));
    return lr_k_pa * 1000.0;
}

double radiative_heat_flux_w_m2(double skin_temp_c, double wall_temp_c, double emissivity,
                                double radiating_area_fraction) {
    require_in_range("emissivity", emissivity, 0.0, 1.0, "");
    const double ts_k = skin_temp_c + kelvin_offset;
    const double tw_k = wall_temp_c + kelvin_offset;
    return radiating_area_fraction * emissivity * stefan_boltzmann_w_m2_k4 *
           (ts_k * ts_k * ts_k * ts_k - tw_k * tw_k * tw_k * tw_k);
}

double radiative_coefficient_w_m2k(double skin_temp_c, double wall_temp_c, double emissivity,
                                   double radiating_area_fraction) {
    const double mean_k = 0.5 * (skin_temp_c + wall_temp_c) + kelvin_offset;
    return 4.0 * radiating_area_fraction * emissivity * stefan_boltzmann_w_m2_k4 * std::pow(mean_k, 3.0);
}

}  // namespace manikind::physics
