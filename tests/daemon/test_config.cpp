#include <catch2/catch.hpp>

#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/config.hpp"
#include "drivers/register_map.hpp"
#include "daemon/setup_record.hpp"
#include "base/user_error.hpp"

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
    CHECK(c.devices.datalogger.max_gap_registers == 16);
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
    // A Modbus request spans at most 125 registers, so a hole wider than 124 can never be bridged.
    CHECK_THROWS_WITH(config::parse_config("[devices.datalogger]\nmax_gap_registers = 200\n", "x.toml"),
                      Catch::Contains("x.toml:2:") && Catch::Contains("devices.datalogger.max_gap_registers") &&
                          Catch::Contains("outside 0..124"));
    CHECK(config::parse_config("[devices.chamber]\nmax_gap_registers = 0\n", "x.toml").devices.chamber.max_gap_registers == 0);
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

TEST_CASE("config: [lab] chamber and manikin name the instruments, a real lab that omits them is warned, not given the "
          "simulated ones",
          "[config]") {
    const auto simulated = config::parse_config("[recorder]\ncommit_interval_s = 2\n", "sim.toml");
    CHECK_THAT(simulated.chamber, Catch::Contains("simulated"));
    CHECK(simulated.warnings.empty());
    const auto unnamed = config::parse_config("[lab]\nmode = \"real\"\n", "lab.toml");
    CHECK(unnamed.chamber.empty());
    CHECK(unnamed.manikin.empty());
    REQUIRE(unnamed.warnings.size() == 2);
    CHECK_THAT(unnamed.warnings[0], Catch::Contains("lab.toml") && Catch::Contains("[lab] chamber is not set"));
    const auto named = config::parse_config("[lab]\nmode = \"real\"\nchamber = \"Weiss WK3 #58226\"\nmanikin = \"ANDI #12\"\n",
                                            "lab.toml");
    CHECK(named.chamber == "Weiss WK3 #58226");
    CHECK(named.manikin == "ANDI #12");
    CHECK(named.warnings.empty());
    CHECK(named.source_text.find("ANDI #12") != std::string::npos);
}

TEST_CASE("config: a trial's set-up records the Type B specifications (Table S2), the register maps and the text",
          "[config]") {
    const auto c = config::parse_config("[lab]\nname = \"room 1.12\"\n[instruments.air_temp_c]\naccuracy = 0.3\n", "lab.toml");
    const auto setup = setup_of(c);
    CHECK(setup.lab_name == "room 1.12");
    CHECK(setup.config_toml == c.source_text);
    const auto calibration = nlohmann::json::parse(setup.calibration_json);
    CHECK(calibration["instruments"]["air_temp_c"]["accuracy"] == 0.3);
    CHECK(calibration["instruments"]["air_rh_pct"]["accuracy"] == 1.4);  // Table S2, from the defaults
    CHECK(calibration["instruments"]["air_rh_pct"]["accuracy_of_reading"] == 0.01);
    CHECK(calibration["register_maps"]["datalogger"]["setting"] == "builtin");
    CHECK(calibration["register_maps"]["datalogger"]["toml"] == std::string(builtin_datalogger_registers_toml()));
    CHECK(calibration["steady_state"]["max_skin_fluctuation_c"] == 0.05);
    // The same configuration gives the same set-up (the daemon stores it once).
    CHECK(setup_of(c).sha256() == setup.sha256());
    const auto recalibrated = config::parse_config("[lab]\nname = \"room 1.12\"\n[instruments.air_temp_c]\naccuracy = 0.2\n", "lab.toml");
    CHECK(setup_of(recalibrated).sha256() != setup.sha256());
}

TEST_CASE("config: a set-up keeps the configuration text but not the API token or an archive password", "[config]") {
    const std::string token(64, 'f');
    const std::string text = "[lab]\nname = \"room 1.12\"\n\n[api]\ntoken = \"" + token +
                             "\"   # from manikin config token\nmax_clients = 8\n\n[archive]\n"
                             "postgresql = \"host=archive dbname=manikin password=s3cret\"\nlab_id = \"lab-3\"\n";
    const auto c = config::parse_config(text, "lab.toml");
    const auto setup = setup_of(c);
    CHECK(setup.config_toml.find(token) == std::string::npos);
    CHECK(setup.config_toml.find("s3cret") == std::string::npos);
    CHECK_THAT(setup.config_toml, Catch::Contains("token = \"(redacted)\"") && Catch::Contains("max_clients = 8") &&
                                      Catch::Contains("postgresql = \"(redacted)\"") &&
                                      Catch::Contains("lab_id = \"lab-3\"") && Catch::Contains("name = \"room 1.12\""));
    // What is left is still the same configuration, secrets aside.
    const auto again = config::parse_config(setup.config_toml, "redacted.toml");
    CHECK(again.api.max_clients == 8);
    CHECK(again.archive.lab_id == "lab-3");
    // A conninfo without a password is kept (where the lab forwards is provenance); a URI's
    // user:password@ is a password.
    CHECK(redact_secrets("[archive]\npostgresql = \"host=archive dbname=manikin\"\n") ==
          "[archive]\npostgresql = \"host=archive dbname=manikin\"\n");
    CHECK_THAT(redact_secrets("[archive]\npostgresql = \"postgresql://lab3:pw@archive/manikin\"\n"),
               !Catch::Contains("pw@"));
    CHECK(redact_secrets("not = [toml") == "");
    CHECK(redact_secrets("[api]\ntoken = \"\"\n") == "[api]\ntoken = \"\"\n");  // empty: the daemon makes one
}

TEST_CASE("config: [recorder] durability, commit interval and journal are read and checked with file and line",
          "[config][recorder]") {
    const auto power = config::parse_config("[recorder]\ndurability = \"power\"\n", "test.toml");
    CHECK(power.recorder_durability == "power");
    CHECK(config::default_config().recorder_durability == "process");
    CHECK_THROWS_WITH(config::parse_config("[recorder]\ndurability = \"fsync\"\n", "test.toml"),
                      Catch::Contains("test.toml:2") && Catch::Contains("durability"));
    CHECK(config::default_config().recorder_commit_interval_s == 30.0);
    CHECK(config::default_config().recorder_crash_ring_dir == "/dev/shm");
    CHECK(config::parse_config("[recorder]\ncommit_interval_s = 5\n", "test.toml").recorder_commit_interval_s == 5.0);
    CHECK_THROWS_WITH(config::parse_config("[recorder]\ncommit_interval_s = 0.01\n", "test.toml"),
                      Catch::Contains("test.toml:2") && Catch::Contains("commit_interval_s"));

    CHECK(config::default_config().recorder_journal == "wal");
    CHECK(config::parse_config("[recorder]\njournal = \"rollback\"\n", "test.toml").recorder_journal == "rollback");
    CHECK_THROWS_WITH(config::parse_config("[recorder]\njournal = \"delete\"\n", "test.toml"),
                      Catch::Contains("test.toml:2") && Catch::Contains("journal") && Catch::Contains("rollback"));
}
