#pragma once
// Typed Modbus holding/input registers <-> engineering values: signed/unsigned 16- and 32-bit
// integers and IEEE-754 float32, with scale and offset (value = raw x scale + offset) and the
// word order of 32-bit values (controllers differ: high word first "ABCD", or low word first
// "CDAB"). The register map itself lives in configuration. Pure: no I/O.
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace manikind::protocol::modbus_registers {

enum class RegisterType { int16, uint16, int32, uint32, float32 };
enum class WordOrder { high_word_first, low_word_first };  // ABCD, CDAB

struct RegisterSpec {
    std::string name;              // "chamber_temp_setpoint_c"
    int address = 0;               // zero-based protocol address
    RegisterType type = RegisterType::int16;
    double scale = 1.0;            // e.g. 0.1 for x10 integers
    double offset = 0.0;
    WordOrder word_order = WordOrder::high_word_first;
    bool writable = false;
    double min_value = -1e300;     // engineering limits enforced on writes
    double max_value = 1e300;
};

int register_count(RegisterType type);

// Throws std::invalid_argument when `registers` is shorter than the type needs. A float32 NaN
// or infinity decodes as such (the caller flags the sample out-of-range).
double decode(const RegisterSpec& spec, std::span<const std::uint16_t> registers);

// Throws std::out_of_range naming the register when the value is outside the spec's limits or
// does not fit the raw type after scaling, and std::logic_error when the register is read-only.
std::vector<std::uint16_t> encode(const RegisterSpec& spec, double value);

}  // namespace manikind::protocol::modbus_registers
