// libFuzzer target for protocol/windsonic: arbitrary bytes through the incremental parser and
// parse_payload; every frame that decodes must re-encode to a frame that decodes again.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "protocol/windsonic.hpp"
#include "fuzz/fuzz_check.hpp"

using namespace manikind::protocol::windsonic;


namespace {

// Values a WindSonic can send (the frame's fixed-width fields, a printable node letter):
// beyond them the encoder is not meant to round-trip. (parse_payload on its own accepts a
// control character as the node; the frame parser never passes one to it.)
bool encodable(const Reading& r) {
    return r.node >= 0x20 && r.node <= 0x7e &&
           std::fabs(r.speed) < 1e6 && std::fabs(r.u) < 1e6 && std::fabs(r.v) < 1e6 &&
           r.status >= 0 && r.status <= 0xFF;
}

void check_round_trip(const Reading& r) {
    if (!encodable(r)) return;
    Parser again;
    int readings = 0;
    for (const char c : encode_frame(r))
        if (again.feed(static_cast<std::uint8_t>(c)) == Parser::Event::reading) ++readings;
    FUZZ_CHECK(readings == 1);
    FUZZ_CHECK(again.reading().format == r.format);
    FUZZ_CHECK(again.reading().status == r.status);
    FUZZ_CHECK(again.reading().direction_deg == r.direction_deg);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    Parser p;
    std::uint64_t events = 0, readings = 0;
    for (std::size_t i = 0; i < size; ++i) {
        const auto e = p.feed(data[i]);
        if (e != Parser::Event::none) ++events;
        if (e == Parser::Event::reading) {
            ++readings;
            check_round_trip(p.reading());
        }
    }
    const auto& c = p.counters();
    FUZZ_CHECK(c.frames == readings);
    FUZZ_CHECK(c.frames + c.checksum_errors + c.malformed == events);
    FUZZ_CHECK(c.bytes_discarded <= size);

    const std::string_view text(reinterpret_cast<const char*>(data), size);
    if (const auto r = parse_payload(text)) {
        (void)r->speed_m_s();
        (void)status_text(r->status);
        check_round_trip(*r);
    }
    (void)checksum(text);
    return 0;
}
