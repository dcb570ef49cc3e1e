#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>

#include "tests/cli/run_cli.hpp"

using manikind::test::run_manikin;

TEST_CASE("cli: physics h-c --json gives Eq. 8 at 41 C / 10 % RH and the implied fluxes", "[cli]") {
    const auto r = run_manikin("physics h-c --air-temp 41 --rh 10 --skin-temp 35 --json");
    REQUIRE(r.exit_code == 0);
    const auto j = nlohmann::json::parse(r.out);
    // Eq. 8 near stagnation: N = dT + 146 dC ~ -1 C, so h ~ 0.3 + 1.25 = 1.55.
    CHECK(j.at("buoyancy_drive_c").get<double>() == Approx(-1.0).margin(0.1));
    CHECK(j.at("h_c_w_m2k").get<double>() == Approx(0.3 + 1.25 * std::pow(std::abs(j.at("buoyancy_drive_c").get<double>()), 0.25)));
    CHECK(j.at("q_convection_w_m2").get<double>() == Approx(j.at("h_c_w_m2k").get<double>() * -6.0));
    CHECK(j.at("warnings").empty());
}

TEST_CASE("cli: physics h-c models: dt-only is Eq. S8, table1 picks B by sign, mixed adds Eq. 9", "[cli]") {
    auto j = nlohmann::json::parse(run_manikin("physics h-c --air-temp 25 --rh 50 --wettedness 0 --model dt-only --json").out);
    CHECK(j.at("h_c_w_m2k").get<double>() == Approx(1.36 * std::pow(10.0, 0.3)));
    j = nlohmann::json::parse(run_manikin("physics h-c --air-temp 51 --rh 50 --wettedness 0 --model table1:thigh --json").out);
    CHECK(j.at("h_c_w_m2k").get<double>() == Approx(0.538 + 0.654 * 2.0));  // Table 1, N = -16
    CHECK_FALSE(j.at("warnings").empty());                                   // 51 C is outside the CFD range
    j = nlohmann::json::parse(run_manikin("physics h-c --air-temp 41 --rh 10 --air-speed 0.5 --json").out);
    const double h_f = 10.4 * std::pow(0.5, 0.56);
    CHECK(j.at("h_forced_w_m2k").get<double>() == Approx(h_f));
    CHECK(j.at("h_mixed_w_m2k").get<double>() == Approx(std::cbrt(std::pow(j.at("h_c_w_m2k").get<double>(), 3) + h_f * h_f * h_f)));
}

TEST_CASE("cli: physics stagnation --rh 10 --json is ~41 C (Introduction)", "[cli]") {
    const auto r = run_manikin("physics stagnation --rh 10 --json");
    REQUIRE(r.exit_code == 0);
    CHECK(nlohmann::json::parse(r.out).at("stagnation_air_temp_c").get<double>() == Approx(41.0).margin(0.5));
}

TEST_CASE("cli: physics threshold-speed --grid --json is ~0.03 m/s (Fig. 3C)", "[cli]") {
    const auto r = run_manikin("physics threshold-speed --grid --json");
    REQUIRE(r.exit_code == 0);
    const auto j = nlohmann::json::parse(r.out);
    CHECK(j.at("threshold_speed_m_s").get<double>() == Approx(0.03).margin(0.005));
    CHECK(j.at("max_free_to_forced_ratio").get<double>() == Approx(0.54).margin(0.005));
}

TEST_CASE("cli: non-physical inputs exit 2 with the option named, never a NaN", "[cli]") {
    auto r = run_manikin("physics h-c --air-temp 41 --rh 120 --json 2>&1");
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.out, Catch::Contains("--rh"));
    r = run_manikin("physics h-c --air-temp 41 --rh 10 --air-speed -1 2>&1");
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.out, Catch::Contains("--air-speed"));
    r = run_manikin("physics h-c --air-temp 41 --rh 10 --model table1:elbow 2>&1");
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.out, Catch::Contains("unknown segment"));
    r = run_manikin("physics stagnation --rh 100 2>&1");
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.out, Catch::Contains("no stagnation temperature"));
    CHECK_THAT(r.out, !Catch::Contains("nan"));
}

TEST_CASE("cli: selfcheck passes every paper number", "[cli]") {
    const auto r = run_manikin("selfcheck --json");
    REQUIRE(r.exit_code == 0);
    const auto j = nlohmann::json::parse(r.out);
    CHECK(j.at("failed").get<int>() == 0);
    CHECK(j.at("passed").get<int>() >= 10);
}
