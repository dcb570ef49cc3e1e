// libFuzzer target for protocol/manikin_can: the input as a struct can_frame (when it has at
// least sizeof(can_frame) = 16 bytes) and as a candump -l line. What decodes is re-encoded and
// must decode again, to the same message type; a candump line must survive write + parse.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "protocol/manikin_can.hpp"
#include "fuzz/fuzz_check.hpp"

using namespace manikind::protocol::manikin_can;


namespace {

bool same_frame(const can_frame& a, const can_frame& b) {
    return a.can_id == b.can_id && a.can_dlc == b.can_dlc && std::memcmp(a.data, b.data, 8) == 0;
}

// Re-encodes a decoded message; the frame must decode to the same alternative, and encoding
// that again must give the same bytes (encode/decode are stable after one pass).
void check_reencode(const Message& m) {
    if (std::holds_alternative<BusError>(m)) return;  // received only, never encoded
    const can_frame f1 = std::visit([](const auto& msg) -> can_frame {
        if constexpr (std::is_same_v<std::decay_t<decltype(msg)>, BusError>) return can_frame{};
        else return encode(msg);
    }, m);
    const auto d1 = decode(f1);
    FUZZ_CHECK(std::holds_alternative<Message>(d1));
    const Message& m1 = std::get<Message>(d1);
    FUZZ_CHECK(m1.index() == m.index());
    const can_frame f2 = std::visit([](const auto& msg) -> can_frame {
        if constexpr (std::is_same_v<std::decay_t<decltype(msg)>, BusError>) return can_frame{};
        else return encode(msg);
    }, m1);
    FUZZ_CHECK(same_frame(f1, f2));
}

void check_frame(const can_frame& f) {
    const auto d = decode(f);
    if (std::holds_alternative<Message>(d)) check_reencode(std::get<Message>(d));
    else FUZZ_CHECK(!std::get<DecodeError>(d).reason.empty());
}

// A frame written as a candump line parses back with the same payload; a second pass is the
// identity (the first may normalise flag bits of the identifier).
void check_candump(const can_frame& f, double t) {
    const auto p1 = parse_candump_line(to_candump_line(f, t));
    FUZZ_CHECK(p1.has_value());
    const std::uint8_t dlc = f.can_dlc > 8 ? 8 : f.can_dlc;
    FUZZ_CHECK(p1->second.can_dlc == dlc);
    FUZZ_CHECK(std::memcmp(p1->second.data, f.data, dlc) == 0);
    const auto p2 = parse_candump_line(to_candump_line(p1->second, p1->first));
    FUZZ_CHECK(p2.has_value());
    FUZZ_CHECK(same_frame(p1->second, p2->second));
    check_frame(p1->second);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size >= sizeof(can_frame)) {
        can_frame f;
        std::memcpy(&f, data, sizeof f);
        check_frame(f);
        check_candump(f, 1718000000.123456);
    }
    const std::string line(reinterpret_cast<const char*>(data), size);
    if (const auto parsed = parse_candump_line(line)) {
        check_frame(parsed->second);
        // timestamps a real log carries; to_candump_line formats into a fixed-size head
        if (std::isfinite(parsed->first) && std::fabs(parsed->first) < 1e15)
            check_candump(parsed->second, parsed->first);
    }
    return 0;
}
