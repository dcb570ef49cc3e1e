#pragma once
// A Modbus register map from TOML (config/chamber_registers.toml): each register's unit id,
// address, type, scaling and write limits. Errors name the file, line and key.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <optional>

#include "drivers/modbus_driver.hpp"
#include "protocol/modbus_registers.hpp"
#include "protocol/probe_scaling.hpp"

namespace manikind {

struct MappedRegister {
    protocol::modbus_registers::RegisterSpec spec;
    int unit_id = 1;
    std::optional<protocol::ProbeScaling> probe;  // analog probe on a datalogger input ([probes.*])
    double valid_min = -1e300, valid_max = 1e300;  // physical range of the value (out-of-range flag)
};

struct RegisterMap {
    std::string family;
    std::vector<MappedRegister> registers;
    const MappedRegister& at(const std::string& name) const;  // throws UserError naming it
};

RegisterMap parse_register_map(const std::string& toml_text, const std::string& source_name);
RegisterMap load_register_map(const std::filesystem::path& path);

// The shipped maps, compiled in (config/chamber_registers.toml, config/datalogger_registers.toml).
const char* builtin_chamber_registers_toml();
const char* builtin_datalogger_registers_toml();
// A config setting: "builtin" (the shipped map for `device`: chamber | datalogger) or a path,
// relative paths resolving from `base_dir`.
RegisterMap register_map_from_setting(const std::string& setting, const std::string& device,
                                      const std::filesystem::path& base_dir);
// The TOML text behind the same setting (what a trial's set-up records).
std::string register_map_text(const std::string& setting, const std::string& device,
                              const std::filesystem::path& base_dir);

// Modbus points from a register map (channel = register name; setpoints are not polled).
std::vector<drivers::ModbusPoint> modbus_points(const RegisterMap& map);

}  // namespace manikind
