#pragma once
// Moist-air psychrometrics. Temperatures in °C at the interface; kelvin only inside.

namespace manikind::physics {

// Saturation vapour pressure over liquid water, Pa. The seed code's formula (MATLAB model,
// Supplementary code; also docs/twin-baseline.md): p_sat = exp(77.3450 + 0.0057 T - 7235/T) / T^8.2,
// T in kelvin. Validity: 0..100 °C over liquid water (0.3-0.45 % below IAPWS-95 there, see tests);
// throws std::domain_error outside -40..200 °C.
double saturation_vapour_pressure_pa(double temp_c);

// Saturation vapour pressure over liquid water, Pa, by IAPWS's saturation-pressure equation
// (Wagner & Pruss 1993, the IAPWS 1992 supplementary release; within 0.01 % of IAPWS-95 from 0 to
// 100 °C). The clothing tests' Ret uses it (issue 63: the seed formula sits 0.39 % below at
// 35 °C, a bias on Ret, Rea and Recl no interval showed); the twin keeps the paper's formula above.
double saturation_vapour_pressure_iapws_pa(double temp_c);

// Partial pressure of water vapour at the given relative humidity (0..100 %), Pa.
double vapour_pressure_pa(double temp_c, double rh_pct);

// Water-vapour mass concentration, kg/m³: C = p M_w / (R T), T = temp_c + 273.15 (Eq. 1 text).
double vapour_concentration_kg_m3(double vapour_pressure_pa, double temp_c);

// Vapour concentration of saturated air at temp_c (a wet skin surface), kg/m³.
double saturation_concentration_kg_m3(double temp_c);

// Density of moist air as an ideal mixture of dry air and water vapour, kg/m³.
double moist_air_density_kg_m3(double temp_c, double vapour_pressure_pa,
                               double total_pressure_pa = 101325.0);

// Humidity ratio (mixing ratio), kg water per kg dry air.
double humidity_ratio_kg_kg(double vapour_pressure_pa, double total_pressure_pa = 101325.0);

// Relative humidity (%) of air at temp_c that holds the given humidity ratio.
double relative_humidity_from_ratio_pct(double temp_c, double humidity_ratio_kg_kg,
                                        double total_pressure_pa = 101325.0);

}  // namespace manikind::physics
