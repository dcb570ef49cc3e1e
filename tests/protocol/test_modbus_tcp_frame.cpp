// Modbus TCP framing (protocol/modbus_tcp_frame.hpp): the MBAP length decides where an ADU ends.
#include <catch2/catch.hpp>

#include <cstdint>
#include <vector>

#include "protocol/modbus_tcp_frame.hpp"

using namespace manikind::protocol::modbus_tcp;

namespace {
// Read holding registers (function 3), 2 registers from address 0x0010, unit 1, transaction 0x1234.
const std::vector<std::uint8_t> kRead = {0x12, 0x34, 0x00, 0x00, 0x00, 0x06, 0x01, 0x03, 0x00, 0x10, 0x00, 0x02};
}  // namespace

TEST_CASE("Modbus TCP framing: an ADU is 6 + the MBAP length, whole or not yet", "[protocol][modbus]") {
    const auto whole = first_frame(kRead.data(), kRead.size());
    CHECK(whole.state == FrameState::complete);
    CHECK(whole.size == 12);
    for (std::size_t n = 0; n < kRead.size(); ++n) CHECK(first_frame(kRead.data(), n).state == FrameState::need_more);
    // Two requests back to back: the first is cut at its own end.
    std::vector<std::uint8_t> two = kRead;
    two.insert(two.end(), kRead.begin(), kRead.end());
    CHECK(first_frame(two.data(), two.size()).size == 12);
}

TEST_CASE("Modbus TCP framing: a protocol id other than 0 or a length outside 2..254 is malformed, as soon as it shows",
          "[protocol][modbus]") {
    auto with = [](std::size_t at, std::uint8_t v) {
        auto b = kRead;
        b[at] = v;
        return b;
    };
    const auto protocol = with(3, 0x01);
    CHECK(first_frame(protocol.data(), 4).state == FrameState::malformed);  // before the length has arrived
    auto length = [&](unsigned l) {
        auto b = kRead;
        b[4] = static_cast<std::uint8_t>(l >> 8);
        b[5] = static_cast<std::uint8_t>(l & 0xff);
        return first_frame(b.data(), b.size()).state;
    };
    CHECK(length(0) == FrameState::malformed);
    CHECK(length(1) == FrameState::malformed);   // a unit id and no function code
    CHECK(length(2) == FrameState::complete);    // unit id + function code: whole at 8 bytes
    CHECK(length(254) == FrameState::need_more);  // 260 bytes, the largest ADU
    CHECK(length(255) == FrameState::malformed);
    CHECK(length(0xffff) == FrameState::malformed);
}
