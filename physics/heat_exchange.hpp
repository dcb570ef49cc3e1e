#pragma once
// Evaporative and radiative heat exchange of a skin surface. Fluxes in W/m², positive = heat lost.

namespace manikind::physics {

// Eq. 1 / Eq. S5: Q_e = 16.5 h_c (p_sk - p_air) omega, pressures in Pa at the interface
// (converted to kPa inside). Negative when p_sk < p_air (condensation); callers that do not
// model condensation clamp at zero.
double evaporative_heat_flux_w_m2(double h_c_w_m2k, double skin_vapour_pressure_pa,
                                  double air_vapour_pressure_pa, double skin_wettedness,
                                  double lewis_relation_k_kpa = 16.5);

// Eq. S4: the Lewis relation from properties, LR = lambda M_v / (p c_p Le^(2/3) M_air), K/kPa.
// Text S1 evaluates it with air properties at 25 °C and the latent heat at a 32 °C skin.
double lewis_relation_from_properties_k_kpa(double air_temp_c, double skin_temp_c,
                                            double total_pressure_pa = 101325.0);

// Latent heat of vaporisation of water, J/kg (linear fit, 0..60 °C).
double latent_heat_vaporisation_j_kg(double temp_c);

// Grey-body exchange with a large enclosure: q = f eps sigma (T_s^4 - T_w^4), temperatures in K inside.
double radiative_heat_flux_w_m2(double skin_temp_c, double wall_temp_c, double emissivity,
                                double radiating_area_fraction = 1.0);

// Linearised radiative coefficient h_r = 4 f eps sigma T_mean^3, W/(m²·K), T_mean the mean of
// skin and wall in kelvin; q ~ h_r (T_s - T_w).
double radiative_coefficient_w_m2k(double skin_temp_c, double wall_temp_c, double emissivity,
                                   double radiating_area_fraction = 1.0);

}  // namespace manikind::physics
