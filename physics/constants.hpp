#pragma once
// Physical constants used across physics/. Values and sources as printed in the paper
// (Viswanathan et al. 2026, "Perspiration vapor lightens near-skin air") unless noted.

namespace manikind::physics {

inline constexpr double kelvin_offset = 273.15;             // °C -> K
inline constexpr double gravity_m_s2 = 9.81;                 // Results: g = 9.81 m/s²
inline constexpr double gas_constant_j_mol_k = 8.314;        // Eq. 1 text: R = 8.314 J/(mol·K)
inline constexpr double molar_mass_water_kg_mol = 0.01802;   // Eq. 1 text: M_w = 18.02 g/mol
inline constexpr double molar_mass_dry_air_kg_mol = 0.02897; // CRC handbook; the paper rounds to 29 g/mol
inline constexpr double compositional_expansion_numerator = 0.607; // beta_C = (MW_a/MW_C - 1)/rho = 0.607/rho
inline constexpr double standard_pressure_pa = 101325.0;
inline constexpr double stefan_boltzmann_w_m2_k4 = 5.670374e-8;
inline constexpr double lewis_relation_k_kpa = 16.5;          // Eq. S5: LR = 16.5 K/kPa
inline constexpr double manikin_height_m = 1.8;               // Fig. 3A: characteristic length L = 1.8 m
inline constexpr double buoyancy_coefficient_eq8 = 146.0;     // Eq. 8: dT + 146 dC

}  // namespace manikind::physics
