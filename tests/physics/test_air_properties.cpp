#include <catch2/catch.hpp>

#include "physics/air_properties.hpp"
#include "physics/buoyancy.hpp"
#include "tests/physics/paper_csv.hpp"

using namespace manikind::physics;

TEST_CASE("Table S5: interpolated properties reproduce every printed row", "[physics][air]") {
    for (const auto& row : manikind::test::read_paper_csv("air_properties_table_s5.csv")) {
        const double temp_c = manikind::test::num(row, "t_air_c");
        INFO("T = " << temp_c << " C");
        const auto p = air_properties(temp_c);
        CHECK(p.warnings.empty());
        CHECK(p.properties.conductivity_w_m_k == Approx(manikind::test::num(row, "k_w_mk")).epsilon(1e-6));
        CHECK(p.properties.kinematic_viscosity_m2_s == Approx(manikind::test::num(row, "nu_m2_s")).epsilon(1e-6));
        CHECK(p.properties.thermal_diffusivity_m2_s == Approx(manikind::test::num(row, "alpha_m2_s")).epsilon(1e-6));
        CHECK(p.properties.thermal_expansion_1_k == Approx(manikind::test::num(row, "beta_t_1_k")).epsilon(1e-6));
        // Text S8: Marrero-Mason D reproduces Table S5's D column to its 5 printed digits.
        CHECK(p.properties.vapour_diffusivity_m2_s == Approx(manikind::test::num(row, "d_m2_s")).epsilon(2e-4));
    }
}

TEST_CASE("Table S5: beta_T column is 1/T (Results: reciprocal of the absolute temperature)", "[physics][air]") {
    CHECK(thermal_expansion_1_k(35.0) == Approx(0.00324517).epsilon(1e-5));
}

TEST_CASE("Table S5: between rows is interpolated, outside 20..50 C warns", "[physics][air]") {
    const auto mid = air_properties(37.5);
    CHECK(mid.properties.conductivity_w_m_k == Approx(0.5 * (0.026913 + 0.0272859)));
    CHECK(mid.warnings.empty());
    const auto cold = air_properties(10.0);
    REQUIRE(cold.warnings.size() == 1);
    CHECK_THAT(cold.warnings[0], Catch::Contains("Table S5"));
}

TEST_CASE("Discussion: Pr = 0.70 and Sc = 0.62 at 35 C", "[physics][air]") {
    const auto p = air_properties(35.0).properties;
    CHECK(p.kinematic_viscosity_m2_s / p.thermal_diffusivity_m2_s == Approx(0.70).margin(0.006));
    CHECK(p.kinematic_viscosity_m2_s / p.vapour_diffusivity_m2_s == Approx(0.62).margin(0.005));
}
