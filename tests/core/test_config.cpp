#include <catch2/catch.hpp>

#include <fstream>
#include <string>

#include "daemon/core/config.hpp"
#include "daemon/core/user_error.hpp"

using namespace manikind;

TEST_CASE("config: the built-in default is config/manikind.toml and parses without warnings", "[config]") {
    std::ifstream in(std::string(MANIKIND_CONFIG_DIR) + "/manikind.toml");
    const std::string file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    CHECK(file == config::default_config_toml());
    const auto c = config::default_config();
    CHECK(c.warnings.empty());
    CHECK(c.mode == "simulated");
    CHECK(c.steady_state.window_s == 1800.0);                 // Methods: final 30 min
    CHECK(c.steady_state.max_skin_fluctuation_c == 0.05);     // Methods: < 0.05 C
    REQUIRE(c.instruments.count("air_rh_pct") == 1);
    CHECK(c.instruments.at("air_rh_pct").accuracy == 1.4);   // Table S2: EE181 ±(1.4 + 0.01 RH) %
    CHECK(c.instruments.at("air_rh_pct").accuracy_of_reading == 0.01);
}

TEST_CASE("config: a wrong type names file, line, column and key", "[config]") {
    const std::string text = "[safety]\nmax_skin_temp_c = \"hot\"\n";
    CHECK_THROWS_WITH(config::parse_config(text, "lab.toml"),
                      Catch::Contains("lab.toml:2:") && Catch::Contains("safety.max_skin_temp_c") &&
                          Catch::Contains("expected a number") && Catch::Contains("found a string"));
}

TEST_CASE("config: out-of-range and inconsistent limits are refused", "[config]") {
    CHECK_THROWS_WITH(config::parse_config("[safety]\nmax_chamber_rh_pct = 120\n", "x.toml"),
                      Catch::Contains("x.toml:2:") && Catch::Contains("outside 0..100"));
    CHECK_THROWS_WITH(config::parse_config("[safety]\nmin_skin_temp_c = 40\nmax_skin_temp_c = 30\n", "x.toml"),
                      Catch::Contains("min_*"));
    CHECK_THROWS_WITH(config::parse_config("[lab]\nmode = \"virtual\"\n", "x.toml"),
                      Catch::Contains("x.toml:2:") && Catch::Contains("lab.mode") && Catch::Contains("real, simulated"));
}

TEST_CASE("config: unknown keys are warnings with their line, known values still apply", "[config]") {
    const auto c = config::parse_config("[safety]\nmax_skin_temp_c = 40\nmax_skn_temp_c = 41\n[extra]\na = 1\n", "lab.toml");
    CHECK(c.safety.max_skin_temp_c == 40.0);
    REQUIRE(c.warnings.size() == 2);
    CHECK_THAT(c.warnings[0] + c.warnings[1], Catch::Contains("lab.toml:3:") && Catch::Contains("safety.max_skn_temp_c"));
    CHECK_THAT(c.warnings[0] + c.warnings[1], Catch::Contains("lab.toml:4:") && Catch::Contains("extra"));
    // keys absent from the file keep the defaults
    CHECK(c.safety.max_chamber_temp_c == config::default_config().safety.max_chamber_temp_c);
}

TEST_CASE("config: TOML syntax errors and missing files name the file and line", "[config]") {
    CHECK_THROWS_WITH(config::parse_config("[safety\nmax = 1\n", "broken.toml"), Catch::Contains("broken.toml:1:"));
    CHECK_THROWS_AS(config::load_config("/nonexistent/manikind.toml"), UserError);
    CHECK_THROWS_WITH(config::load_config("/nonexistent/manikind.toml"), Catch::Contains("cannot open"));
}
