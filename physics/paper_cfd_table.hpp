#pragma once
// The paper's parametric CFD study (Tables S8-S10, as shipped in
// tests/data/paper/cfd_whole_body_cases.csv): whole-body h and evaporative flux for a
// water-saturated 35 °C skin. Embedded so `manikin selfcheck` runs without data files; a test
// checks that this table equals the CSV.
#include <span>

namespace manikind::physics {

struct CfdCase {
    int case_id;
    double air_temp_c;
    double air_rh_pct;
    double dt_skin_air_c;       // T_sk - T_air
    double h_sim_w_m2k;         // CFD whole-body free convection coefficient
    double q_sim_w_m2;          // CFD evaporative heat flux
    double h_dt_only_w_m2k;     // Eq. S8 as tabulated
    double q_dt_only_w_m2;      // Eq. S9 as tabulated
};

inline constexpr double cfd_skin_temp_c = 35.0;

std::span<const CfdCase> paper_cfd_cases();

}  // namespace manikind::physics
