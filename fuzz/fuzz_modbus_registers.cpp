// libFuzzer target for protocol/modbus_registers: a RegisterSpec built from the first input
// bytes (type, word order, scale, offset, limits: any double bit pattern, NaN and infinities
// included) decodes the remaining bytes as register words, then the value is written back
// through encode(). Only the documented exceptions may escape.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "protocol/modbus_registers.hpp"
#include "fuzz/fuzz_check.hpp"

using namespace manikind::protocol::modbus_registers;


namespace {

struct Input {
    const std::uint8_t* p;
    std::size_t n;
    std::uint8_t byte() {
        if (n == 0) return 0;
        --n;
        return *p++;
    }
    double real() {
        std::uint64_t bits = 0;
        for (int i = 0; i < 8; ++i) bits = (bits << 8) | byte();
        double d;
        std::memcpy(&d, &bits, sizeof d);
        return d;
    }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    Input in{data, size};
    RegisterSpec spec;
    spec.name = "fuzz";
    const std::uint8_t kind = in.byte();
    spec.type = static_cast<RegisterType>(kind % 5);
    spec.word_order = (kind & 0x08) ? WordOrder::low_word_first : WordOrder::high_word_first;
    spec.writable = (kind & 0x10) == 0;
    // Plain scales most of the time so the integer paths get exercised, raw bits otherwise.
    const std::uint8_t how = in.byte();
    spec.scale = (how & 1) ? in.real() : 1.0 / static_cast<double>(1 + (how >> 1));
    spec.offset = (how & 2) ? in.real() : 0.0;
    if (how & 4) {
        spec.min_value = in.real();
        spec.max_value = in.real();
    }
    std::vector<std::uint16_t> words;
    while (in.n >= 2) {
        const int hi = in.byte();
        const int lo = in.byte();
        words.push_back(static_cast<std::uint16_t>((hi << 8) | lo));
    }

    double value = 0.0;
    try {
        value = decode(spec, words);
    } catch (const std::invalid_argument&) {
        FUZZ_CHECK(words.size() < static_cast<std::size_t>(register_count(spec.type)));
        return 0;
    }
    try {
        const auto raw = encode(spec, value);
        FUZZ_CHECK(raw.size() == static_cast<std::size_t>(register_count(spec.type)));
        (void)decode(spec, raw);
    } catch (const std::out_of_range&) {
    } catch (const std::logic_error&) {
        FUZZ_CHECK(!spec.writable);
    }
    return 0;
}
