#pragma once
// Thermal and compositional (water-vapour) buoyancy near the skin: Results, Table S4, Eq. 2.
// Sign convention: positive = the near-skin air is lighter than the far field (ascending plume).

#include <optional>
#include <string>
#include <vector>

namespace manikind::physics {

struct SkinAirState {
    double skin_temp_c = 35.0;
    double air_temp_c = 35.0;
    double air_rh_pct = 50.0;
    double skin_wettedness = 1.0;                 // omega: 0 dry, 1 water-saturated
    double characteristic_length_m = 1.8;         // Fig. 3A: L = manikin height
    double total_pressure_pa = 101325.0;
};

struct BuoyancyResult {
    double dt_c = 0.0;                 // T_sk - T_air
    double dc_kg_m3 = 0.0;             // omega (C_sk,sat - C_air) (Limitations: dC scales with omega)
    double film_temp_c = 0.0;          // (T_sk + T_air)/2
    double film_density_kg_m3 = 0.0;   // moist air at film temperature and mean vapour pressure
    double beta_t_1_k = 0.0;           // 1 / T_film
    double beta_c_m3_kg = 0.0;         // 0.607 / rho_film
    double b_dt_n_m3 = 0.0;            // B_dT = g rho beta_T dT
    double b_dc_n_m3 = 0.0;            // B_dC = g rho beta_C dC
    double b_net_n_m3 = 0.0;           // B_dT + B_dC
    double ra_dt = 0.0;                // Eq. 2 thermal term
    double ra_dc = 0.0;                // Eq. 2 concentration term
    double ra_total = 0.0;             // Eq. 2
    double coupling_coefficient = 0.0; // beta_C alpha / (beta_T D), Eq. 7 (~146)
    std::vector<std::string> warnings; // inputs outside Table S5's 20..50 °C
};

// All of the above at film conditions (Eq. 2 text: properties at the mean of skin and air).
BuoyancyResult buoyancy(const SkinAirState& state);

// beta_C alpha / (beta_T D) at film conditions (Discussion: 145.7 at 35 °C, 146.9 with 37 °C skin).
double coupling_coefficient(const SkinAirState& state);

// Stagnation air temperature (Table S4): the air temperature above the skin temperature at which
// B_net = 0 for a water-saturated skin at skin_temp_c and air at rh_pct. Empty when the two
// buoyancies do not cancel between skin_temp_c and skin_temp_c + 40 °C (e.g. RH = 100 %).
std::optional<double> stagnation_air_temp_c(double rh_pct, double skin_temp_c = 35.0,
                                            double skin_wettedness = 1.0);

}  // namespace manikind::physics
