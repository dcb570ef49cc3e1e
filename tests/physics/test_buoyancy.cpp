#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>

#include "physics/buoyancy.hpp"
#include "physics/paper_cfd_table.hpp"

using namespace manikind::physics;

namespace {
SkinAirState wet_skin(double skin_c, double air_c, double rh_pct) {
    SkinAirState s;
    s.skin_temp_c = skin_c;
    s.air_temp_c = air_c;
    s.air_rh_pct = rh_pct;
    s.skin_wettedness = 1.0;
    return s;
}
}  // namespace

TEST_CASE("Discussion: beta_C alpha/(beta_T D) = 145.7 with all properties at 35 C", "[physics][buoyancy]") {
    CHECK(coupling_coefficient(wet_skin(35.0, 35.0, 10.0)) == Approx(145.7).margin(0.5));
}

TEST_CASE("Discussion: the coefficient rises to 146.9 with a 37 C skin", "[physics][buoyancy]") {
    // Film at 36 C (37 C skin, 35 C air); the paper gives no RH: we get 146.6 at 10 % RH.
    const double gamma = coupling_coefficient(wet_skin(37.0, 35.0, 10.0));
    CHECK(gamma == Approx(146.9).margin(0.5));
    CHECK(gamma > coupling_coefficient(wet_skin(35.0, 35.0, 10.0)));
}

TEST_CASE("Discussion: mean coefficient over the CFD cases is 145.7 +- 3.7", "[physics][buoyancy]") {
    double sum = 0.0;
    int n = 0;
    for (const auto& c : paper_cfd_cases()) {
        sum += coupling_coefficient(wet_skin(cfd_skin_temp_c, c.air_temp_c, c.air_rh_pct));
        ++n;
    }
    CHECK(sum / n == Approx(145.7).margin(3.7));
}

TEST_CASE("Discussion: |Ra_T| of the CFD cases reaches 1.1e10", "[physics][buoyancy]") {
    double ra_max = 0.0;
    for (const auto& c : paper_cfd_cases())
        ra_max = std::max(ra_max, std::abs(buoyancy(wet_skin(cfd_skin_temp_c, c.air_temp_c, c.air_rh_pct)).ra_total));
    CHECK(ra_max == Approx(1.1e10).epsilon(0.05));
}

TEST_CASE("Table S4: buoyancy signs in each regime at 10 % RH", "[physics][buoyancy]") {
    const auto cool = buoyancy(wet_skin(35.0, 30.0, 10.0));  // T_air < T_sk: both up
    CHECK(cool.b_dt_n_m3 > 0.0);
    CHECK(cool.b_dc_n_m3 > 0.0);
    const auto warm = buoyancy(wet_skin(35.0, 38.0, 10.0));  // T_sk < T_air < T_stag: humidity wins
    CHECK(warm.b_dt_n_m3 < 0.0);
    CHECK(warm.b_net_n_m3 > 0.0);
    const auto hot = buoyancy(wet_skin(35.0, 45.0, 10.0));  // T_air > T_stag: thermal wins, down
    CHECK(hot.b_dc_n_m3 > 0.0);
    CHECK(hot.b_net_n_m3 < 0.0);
}

TEST_CASE("Buoyancy: B_dC = g 0.607 dC and B_dT = g rho beta_T dT (Results)", "[physics][buoyancy]") {
    const auto b = buoyancy(wet_skin(35.0, 41.0, 10.0));
    CHECK(b.b_dc_n_m3 == Approx(9.81 * 0.607 * b.dc_kg_m3));
    CHECK(b.b_dt_n_m3 == Approx(9.81 * b.film_density_kg_m3 * b.dt_c / (38.0 + 273.15)));
    CHECK(b.ra_total == Approx(b.ra_dt + b.ra_dc));
}

TEST_CASE("Introduction: 41 C air at 10 % RH is near-neutral for a 35 C wet skin", "[physics][buoyancy]") {
    const auto stagnation_c = stagnation_air_temp_c(10.0, 35.0);
    REQUIRE(stagnation_c.has_value());
    CHECK(*stagnation_c == Approx(41.0).margin(0.5));
    // and the net buoyancy there is small next to either component
    const auto b = buoyancy(wet_skin(35.0, 41.0, 10.0));
    CHECK(std::abs(b.b_net_n_m3) < 0.1 * std::abs(b.b_dt_n_m3));
}

TEST_CASE("Results: stagnation moves toward the skin temperature as RH rises, none at 100 %", "[physics][buoyancy]") {
    const double t10 = *stagnation_air_temp_c(10.0);
    const double t50 = *stagnation_air_temp_c(50.0);
    const double t90 = *stagnation_air_temp_c(90.0);
    CHECK(t10 > t50);
    CHECK(t50 > t90);
    CHECK(t90 > 35.0);
    CHECK_FALSE(stagnation_air_temp_c(100.0).has_value());
}

TEST_CASE("Limitations: partial wettedness scales dC linearly", "[physics][buoyancy]") {
    auto half = wet_skin(35.0, 41.0, 10.0);
    half.skin_wettedness = 0.5;
    CHECK(buoyancy(half).dc_kg_m3 == Approx(0.5 * buoyancy(wet_skin(35.0, 41.0, 10.0)).dc_kg_m3));
    auto dry = half;
    dry.skin_wettedness = 0.0;
    CHECK(buoyancy(dry).dc_kg_m3 == 0.0);
    CHECK(buoyancy(dry).b_dc_n_m3 == 0.0);
    dry.skin_wettedness = 1.5;
    CHECK_THROWS(buoyancy(dry));
}
