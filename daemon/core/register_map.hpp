#pragma once
// A Modbus register map from TOML (config/chamber_registers.toml): each register's unit id,
// address, type, scaling and write limits. Errors name the file, line and key.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "protocol/modbus_registers.hpp"

namespace manikind {

struct MappedRegister {
    protocol::modbus_registers::RegisterSpec spec;
    int unit_id = 1;
};

struct RegisterMap {
    std::string family;
    std::vector<MappedRegister> registers;
    const MappedRegister& at(const std::string& name) const;  // throws UserError naming it
};

RegisterMap parse_register_map(const std::string& toml_text, const std::string& source_name);
RegisterMap load_register_map(const std::filesystem::path& path);

}  // namespace manikind
