#include "protocol/modbus_registers.hpp"

#include <bit>
#include <cmath>
#include <cstdio>

#include "protocol/fixed_point.hpp"

namespace manikind::protocol::modbus_registers {
namespace {

std::uint32_t join(std::span<const std::uint16_t> r, WordOrder order) {
    const std::uint32_t hi = order == WordOrder::high_word_first ? r[0] : r[1];
    const std::uint32_t lo = order == WordOrder::high_word_first ? r[1] : r[0];
    return (hi << 16) | lo;
}

std::vector<std::uint16_t> split(std::uint32_t v, WordOrder order) {
    const auto hi = static_cast<std::uint16_t>(v >> 16), lo = static_cast<std::uint16_t>(v & 0xffff);
    return order == WordOrder::high_word_first ? std::vector<std::uint16_t>{hi, lo} : std::vector<std::uint16_t>{lo, hi};
}

std::string describe(const RegisterSpec& s, double value) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "register %s (address %d): %g", s.name.c_str(), s.address, value);
    return buf;
}

}  // namespace

int register_count(RegisterType t) {
    return t == RegisterType::int16 || t == RegisterType::uint16 ? 1 : 2;
}

double decode(const RegisterSpec& s, std::span<const std::uint16_t> r) {
    if (r.size() < static_cast<std::size_t>(register_count(s.type)))
        throw std::invalid_argument("register " + s.name + ": too few registers for its type");
    double raw = 0.0;
    switch (s.type) {
        case RegisterType::int16: raw = static_cast<std::int16_t>(r[0]); break;
        case RegisterType::uint16: raw = r[0]; break;
        case RegisterType::int32: raw = static_cast<std::int32_t>(join(r, s.word_order)); break;
        case RegisterType::uint32: raw = join(r, s.word_order); break;
        case RegisterType::float32: raw = std::bit_cast<float>(join(r, s.word_order)); break;
    }
    return scaled_value(raw, s.scale, s.offset);
}

std::vector<std::uint16_t> encode(const RegisterSpec& s, double value) {
    if (!s.writable) throw std::logic_error(describe(s, value) + " is read-only");
    if (!std::isfinite(value) || value < s.min_value || value > s.max_value) {
        char limits[96];
        std::snprintf(limits, sizeof limits, " is outside the limits %g..%g", s.min_value, s.max_value);
        throw std::out_of_range(describe(s, value) + limits);
    }
    const double raw = (value - s.offset) / s.scale;
    auto fits = [&](double lo, double hi) {
        // Written so that NaN fails too (scale 0 with value == offset gives 0/0): converting
        // NaN to an integer type is undefined behaviour.
        const double rounded = std::round(raw);
        if (!(rounded >= lo && rounded <= hi)) throw std::out_of_range(describe(s, value) + " does not fit the register type");
        return rounded;
    };
    switch (s.type) {
        case RegisterType::int16: return {static_cast<std::uint16_t>(static_cast<std::int16_t>(fits(-32768, 32767)))};
        case RegisterType::uint16: return {static_cast<std::uint16_t>(fits(0, 65535))};
        case RegisterType::int32:
            return split(static_cast<std::uint32_t>(static_cast<std::int32_t>(fits(-2147483648.0, 2147483647.0))), s.word_order);
        case RegisterType::uint32: return split(static_cast<std::uint32_t>(fits(0, 4294967295.0)), s.word_order);
        case RegisterType::float32: return split(std::bit_cast<std::uint32_t>(static_cast<float>(raw)), s.word_order);
    }
    return {};
}

}  // namespace manikind::protocol::modbus_registers
