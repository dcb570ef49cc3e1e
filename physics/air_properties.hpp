#pragma once
// Transport properties of air versus temperature (Table S5, Text S8).

#include "physics/range_check.hpp"

namespace manikind::physics {

struct AirProperties {
    double conductivity_w_m_k = 0.0;        // k
    double kinematic_viscosity_m2_s = 0.0;  // nu
    double thermal_diffusivity_m2_s = 0.0;  // alpha
    double thermal_expansion_1_k = 0.0;     // beta_T as tabulated (1/T)
    double vapour_diffusivity_m2_s = 0.0;   // D, Marrero-Mason
};

inline constexpr double table_s5_min_c = 20.0;
inline constexpr double table_s5_max_c = 50.0;

// Table S5 interpolated linearly between its 5 °C rows; D from Marrero-Mason. Outside
// 20..50 °C the table is extrapolated linearly and a warning is attached.
struct CheckedAirProperties {
    AirProperties properties;
    std::vector<std::string> warnings;
};
CheckedAirProperties air_properties(double temp_c);

// Text S8: D(T) = 0.187e-9 (T + 273.15)^2.072 m²/s, T in °C (Marrero and Mason).
double vapour_diffusivity_m2_s(double temp_c);

// beta_T = 1 / T_film in kelvin, T_film the mean of skin and air (Results, Table S4).
double thermal_expansion_1_k(double film_temp_c);

// beta_C = (MW_a/MW_C - 1)/rho = 0.607/rho, m³/kg (Results; Table S7).
double compositional_expansion_m3_kg(double density_kg_m3);

}  // namespace manikind::physics
