// Fixed-point fields decode to the decimal they count, so exports print "-0.6", not
// "-0.6000000000000001" (issue 16).
#include <catch2/catch.hpp>

#include <charconv>
#include <string>

#include "protocol/fixed_point.hpp"
#include "protocol/manikin_can.hpp"
#include "protocol/modbus_registers.hpp"

using namespace manikind::protocol;

namespace {
std::string shortest(double v) {
    char buf[32];
    const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
    return ec == std::errc() ? std::string(buf, end) : "?";
}
}  // namespace

TEST_CASE("fixed point: hundredths and tenths decode to the decimal's nearest double", "[protocol][fixed_point]") {
    // The multiplication these replaced gives binary noise for both.
    REQUIRE(shortest(-6 * 0.1) == "-0.6000000000000001");
    CHECK(shortest(scaled_value(-6, 0.1)) == "-0.6");
    CHECK(shortest(scaled_value(3674, 0.01)) == "36.74");
    CHECK(shortest(scaled_value(2205, 0.01, 0.0)) == "22.05");
    CHECK(scaled_value(7, 0.5) == 3.5);
    // A scale that is not 1/n keeps the plain product; an offset is still added.
    CHECK(scaled_value(3, 2.5) == 7.5);
    CHECK(scaled_value(0, 0.01, -40.0) == -40.0);
}

TEST_CASE("fixed point: a manikin zone status and a Modbus register print without float noise", "[protocol][fixed_point]") {
    using namespace manikin_can;
    const ZoneStatus sent{7, 36.74, -0.6, 45.6, 20.0, 0};
    const auto decoded = decode(encode(sent));
    REQUIRE(std::holds_alternative<Message>(decoded));
    const auto& z = std::get<ZoneStatus>(std::get<Message>(decoded));
    CHECK(shortest(z.skin_temp_c) == "36.74");
    CHECK(shortest(z.heat_flux_w_m2) == "-0.6");
    CHECK(shortest(z.heater_power_w_m2) == "45.6");

    modbus_registers::RegisterSpec spec;
    spec.name = "air_temp_pv_c";
    spec.type = modbus_registers::RegisterType::int16;
    spec.scale = 0.1;
    const std::uint16_t raw[] = {static_cast<std::uint16_t>(static_cast<std::int16_t>(-6))};
    CHECK(shortest(modbus_registers::decode(spec, raw)) == "-0.6");
}
