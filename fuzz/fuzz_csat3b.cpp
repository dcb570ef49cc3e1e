// libFuzzer target for protocol/csat3b: arbitrary bytes through the incremental parser and
// parse_line; every record that decodes must re-encode to a line that decodes to the same
// record (values to the 5 decimals the encoder writes).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "protocol/csat3b.hpp"
#include "fuzz/fuzz_check.hpp"

using namespace manikind::protocol::csat3b;


namespace {

bool same_value(double a, double b) {
    if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b);
    return std::fabs(a - b) <= 5.000001e-6 || a == b;  // "%.5f" rounds to half a unit of 1e-5
}

void check_round_trip(const Record& r) {
    FUZZ_CHECK(r.counter >= 0 && r.counter <= 63);
    const auto back = parse_line(encode_line(r));
    FUZZ_CHECK(back.has_value());
    FUZZ_CHECK(same_value(back->ux_m_s, r.ux_m_s));
    FUZZ_CHECK(same_value(back->uy_m_s, r.uy_m_s));
    FUZZ_CHECK(same_value(back->uz_m_s, r.uz_m_s));
    FUZZ_CHECK(same_value(back->sonic_temp_c, r.sonic_temp_c));
    FUZZ_CHECK(back->diag == r.diag);
    FUZZ_CHECK(back->counter == r.counter);
    (void)diag_text(r.diag);
    (void)r.speed_m_s();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    Parser p;
    std::uint64_t events = 0, records = 0, terminators = 0;
    for (std::size_t i = 0; i < size; ++i) {
        if (data[i] == '\r' || data[i] == '\n') ++terminators;
        const auto e = p.feed(data[i]);
        if (e != Parser::Event::none) ++events;
        if (e == Parser::Event::record) {
            ++records;
            check_round_trip(p.record());
        }
    }
    const auto& c = p.counters();
    FUZZ_CHECK(c.records == records);
    FUZZ_CHECK(c.records + c.signature_errors + c.malformed == events);
    FUZZ_CHECK(events <= terminators + 1);
    FUZZ_CHECK(c.bytes_discarded <= size);
    FUZZ_CHECK(c.counter_gaps <= c.records);

    const std::string_view text(reinterpret_cast<const char*>(data), size);
    std::string why;
    if (const auto r = parse_line(text, &why)) check_round_trip(*r);
    else FUZZ_CHECK(!why.empty());
    (void)signature(signed_part(text));
    return 0;
}
