#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "protocol/modbus_registers.hpp"

using namespace manikind::protocol::modbus_registers;

TEST_CASE("Modbus registers: x10 signed integers (a chamber setpoint of 41.5 C is 415)", "[protocol][modbus]") {
    RegisterSpec sp{"chamber_temp_setpoint_c", 300, RegisterType::int16, 0.1, 0.0, WordOrder::high_word_first, true, -40, 100};
    CHECK(encode(sp, 41.5) == std::vector<std::uint16_t>{415});
    CHECK(encode(sp, -12.3) == std::vector<std::uint16_t>{static_cast<std::uint16_t>(-123)});
    const std::uint16_t neg = static_cast<std::uint16_t>(-123);
    CHECK(decode(sp, std::span<const std::uint16_t>(&neg, 1)) == Approx(-12.3));
}

TEST_CASE("Modbus registers: float32 in both word orders (IEEE 754: 41.5 = 0x42260000)", "[protocol][modbus]") {
    RegisterSpec abcd{"pv", 0, RegisterType::float32, 1.0, 0.0, WordOrder::high_word_first, true};
    RegisterSpec cdab = abcd;
    cdab.word_order = WordOrder::low_word_first;
    CHECK(encode(abcd, 41.5) == std::vector<std::uint16_t>{0x4226, 0x0000});
    CHECK(encode(cdab, 41.5) == std::vector<std::uint16_t>{0x0000, 0x4226});
    const std::uint16_t regs[] = {0x0000, 0x4226};
    CHECK(decode(cdab, regs) == Approx(41.5));
    CHECK(decode(abcd, regs) != Approx(41.5));  // the wrong word order is not silently right
}

TEST_CASE("Modbus registers: 32-bit integers, offsets, and refusals that name the register", "[protocol][modbus]") {
    RegisterSpec counter{"run_seconds", 10, RegisterType::uint32, 1.0, 0.0, WordOrder::high_word_first, true};
    CHECK(encode(counter, 70000) == std::vector<std::uint16_t>{0x0001, 0x1170});
    RegisterSpec kelvin{"wall_temp_c", 20, RegisterType::uint16, 0.01, -273.15, WordOrder::high_word_first, true, -50, 150};
    const auto raw = encode(kelvin, 25.0);
    CHECK(raw == std::vector<std::uint16_t>{29815});
    CHECK(decode(kelvin, raw) == Approx(25.0));
    CHECK_THROWS_WITH(encode(kelvin, 200.0), Catch::Contains("wall_temp_c") && Catch::Contains("outside the limits"));
    RegisterSpec small{"x10", 1, RegisterType::int16, 0.1, 0.0, WordOrder::high_word_first, true};
    CHECK_THROWS_WITH(encode(small, 5000.0), Catch::Contains("does not fit"));
    RegisterSpec ro{"pv", 2, RegisterType::int16, 0.1, 0.0, WordOrder::high_word_first, false};
    CHECK_THROWS_AS(encode(ro, 1.0), std::logic_error);
    CHECK_THROWS_AS(decode(counter, std::span<const std::uint16_t>()), std::invalid_argument);
}

TEST_CASE("Modbus registers: seeded random round trips for every type", "[protocol][modbus][fuzz]") {
    std::mt19937 rng(502);
    std::uniform_real_distribution<double> value(-3000.0, 3000.0);
    for (auto type : {RegisterType::int16, RegisterType::int32, RegisterType::float32}) {
        for (auto order : {WordOrder::high_word_first, WordOrder::low_word_first}) {
            RegisterSpec s{"r", 0, type, 0.1, 0.0, order, true};
            for (int i = 0; i < 2000; ++i) {
                const double v = std::round(value(rng) * 10.0) / 10.0;
                CHECK(decode(s, encode(s, v)) == Approx(v).margin(1e-3));
            }
        }
    }
}
