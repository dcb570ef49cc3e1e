#include "physics/air_properties.hpp"

#include <array>
#include <cmath>
#include <cstddef>

#include "physics/constants.hpp"

namespace manikind::physics {
namespace {

struct TableS5Row {
    double temp_c;
    double k_w_m_k;
    double nu_m2_s;
    double alpha_m2_s;
    double beta_t_1_k;
};

// Table S5 (Bergman et al. values as interpolated by the authors). D is not tabulated here:
// it comes from the Marrero-Mason formula, which reproduces the table's D column.
constexpr std::array<TableS5Row, 7> table_s5{{
    {20.0, 0.0257787, 1.5243e-05, 2.1553e-05, 0.00341122},
    {25.0, 0.0261598, 1.5714e-05, 2.2243e-05, 0.00335402},
    {30.0, 0.0265378, 1.6191e-05, 2.2941e-05, 0.0032987},
    {35.0, 0.026913, 1.6674e-05, 2.3646e-05, 0.00324517},
    {40.0, 0.0272859, 1.7162e-05, 2.4361e-05, 0.00319336},
    {45.0, 0.0276568, 1.7655e-05, 2.5083e-05, 0.00314317},
    {50.0, 0.0280261, 1.8154e-05, 2.5815e-05, 0.00309454},
}};

double lerp(double a, double b, double f) { return a + (b - a) * f; }

}  // namespace

double vapour_diffusivity_m2_s(double temp_c) {
    return 0.187e-9 * std::pow(temp_c + kelvin_offset, 2.072);  // Text S8
}

double thermal_expansion_1_k(double film_temp_c) { return 1.0 / (film_temp_c + kelvin_offset); }

double compositional_expansion_m3_kg(double density_kg_m3) {
    return compositional_expansion_numerator / density_kg_m3;
}

CheckedAirProperties air_properties(double temp_c) {
    require_in_range("air temperature", temp_c, -40.0, 150.0, "degC");
    CheckedAirProperties out;
    warn_if_outside(out.warnings, "film temperature", temp_c, table_s5_min_c, table_s5_max_c, "degC",
                    "Table S5");
    // Pick the bracketing interval; the first/last interval extrapolates outside the table.
    std::size_t i = 0;
    while (i + 2 < table_s5.size() && temp_c > table_s5[i + 1].temp_c) ++i;
    const TableS5Row& lo = table_s5[i];
    const TableS5Row& hi = table_s5[i + 1];
    const double f = (temp_c - lo.temp_c) / (hi.temp_c - lo.temp_c);
    out.properties.conductivity_w_m_k = lerp(lo.k_w_m_k, hi.k_w_m_k, f);
    out.properties.kinematic_viscosity_m2_s = lerp(lo.nu_m2_s, hi.nu_m2_s, f);
    out.properties.thermal_diffusivity_m2_s = lerp(lo.alpha_m2_s, hi.alpha_m2_s, f);
    out.properties.thermal_expansion_1_k = lerp(lo.beta_t_1_k, hi.beta_t_1_k, f);
    out.properties.vapour_diffusivity_m2_s = vapour_diffusivity_m2_s(temp_c);
    return out;
}

}  // namespace manikind::physics
