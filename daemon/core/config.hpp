#pragma once
// The daemon's configuration, read from TOML. Every error names the file, the line and
// column, and the key (`config/manikind.toml:12:1: safety.max_skin_temp_c: expected a number,
// found a string`). Unknown keys are warnings (a typo must not silently drop a limit, but an
// extra note in a lab's file must not stop a trial either).
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace manikind::config {

struct InstrumentSpec {
    double accuracy = 0.0;             // in the channel's unit
    double accuracy_of_reading = 0.0;  // fraction of |reading|
    std::string distribution = "rectangular";
};

struct SafetyLimits {
    double max_skin_temp_c = 45.0;         // manikin surface setpoint ceiling
    double min_skin_temp_c = 20.0;
    double max_heater_temp_c = 50.0;
    double max_heater_power_w_m2 = 500.0;
    double min_chamber_temp_c = 5.0;
    double max_chamber_temp_c = 55.0;
    double min_chamber_rh_pct = 5.0;
    double max_chamber_rh_pct = 95.0;
    double watchdog_timeout_s = 10.0;      // silence after which heating stops
};

struct SteadyStateRule {
    double window_s = 1800.0;              // Methods: the final 30 min
    double max_skin_fluctuation_c = 0.05;  // Methods: < 0.05 °C
};

struct Config {
    std::string lab_name = "simulated lab";
    std::string mode = "simulated";        // simulated | real
    std::string log_level = "info";
    std::filesystem::path database = "manikind.db";
    SafetyLimits safety;
    SteadyStateRule steady_state;
    std::map<std::string, InstrumentSpec> instruments;  // keyed by channel (air_temp_c, ...)
    std::vector<std::string> warnings;     // unknown keys and similar, with file:line
};

// The text of config/manikind.toml, embedded at build time (CMake writes it into the build tree).
const char* default_config_toml();

// The configuration compiled into the program: the simulated lab (config/manikind.toml).
Config default_config();

// Parses TOML text over the defaults (keys absent from the text keep the default's value);
// `source_name` is used in messages. Throws manikind::UserError.
Config parse_config(const std::string& toml_text, const std::string& source_name);
Config parse_config(const std::string& toml_text, const std::string& source_name, const Config& base);

// Reads and parses a file. Throws manikind::UserError (missing file, syntax, types, ranges).
Config load_config(const std::filesystem::path& path);

}  // namespace manikind::config
