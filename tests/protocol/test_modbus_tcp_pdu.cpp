// The Modbus TCP client's requests and reply checks (protocol/modbus_tcp_pdu.hpp), against the
// examples printed in the Modbus Application Protocol Specification V1.1b3 (6.3, 6.6, 6.12, 7).
#include <catch2/catch.hpp>

#include <cstdint>
#include <stdexcept>
#include <vector>

#include "protocol/modbus_tcp_frame.hpp"
#include "protocol/modbus_tcp_pdu.hpp"

using namespace manikind::protocol::modbus_tcp;

namespace {

std::vector<std::uint8_t> encoded(const Request& q) {
    std::vector<std::uint8_t> out;
    append_request(out, q);
    return out;
}

// An MBAP header (transaction, protocol 0, length, unit) in front of a PDU.
std::vector<std::uint8_t> adu(std::uint16_t transaction, std::uint8_t unit, const std::vector<std::uint8_t>& pdu) {
    std::vector<std::uint8_t> out(7 + pdu.size());
    out[0] = static_cast<std::uint8_t>(transaction >> 8);
    out[1] = static_cast<std::uint8_t>(transaction & 0xff);
    out[5] = static_cast<std::uint8_t>(pdu.size() + 1);
    out[6] = unit;
    for (std::size_t i = 0; i < pdu.size(); ++i) out[7 + i] = pdu[i];
    return out;
}

Request read_108_110() {  // 6.3's example: registers 108-110 (address 0x6B), 3 of them
    Request q;
    q.transaction = 0x0102;
    q.unit = 0x11;
    q.function = kReadHolding;
    q.address = 0x006B;
    q.count = 3;
    return q;
}

}  // namespace

TEST_CASE("Modbus TCP requests: the specification's read, write and multiple-write examples, byte for byte", "[protocol][modbus]") {
    // 6.3: 03 006B 0003, behind the MBAP header (length 6: unit + 5 PDU bytes).
    CHECK(encoded(read_108_110()) == adu(0x0102, 0x11, {0x03, 0x00, 0x6B, 0x00, 0x03}));
    Request input = read_108_110();
    input.function = kReadInput;  // 6.4: the same fields, function 04
    CHECK(encoded(input) == adu(0x0102, 0x11, {0x04, 0x00, 0x6B, 0x00, 0x03}));
    // 6.6: register 2 (address 1) set to 0x0003.
    Request single;
    single.transaction = 7;
    single.unit = 1;
    single.function = kWriteSingle;
    single.address = 1;
    single.count = 1;
    single.values = {0x0003};
    CHECK(encoded(single) == adu(7, 1, {0x06, 0x00, 0x01, 0x00, 0x03}));
    // 6.12: registers 2 and 3 set to 0x000A and 0x0102.
    Request multiple = single;
    multiple.function = kWriteMultiple;
    multiple.count = 2;
    multiple.values = {0x000A, 0x0102};
    CHECK(encoded(multiple) == adu(7, 1, {0x10, 0x00, 0x01, 0x00, 0x02, 0x04, 0x00, 0x0A, 0x01, 0x02}));
    // Each request is one whole ADU for a server's framing.
    const auto bytes = encoded(multiple);
    CHECK(first_frame(bytes.data(), bytes.size()).size == bytes.size());
}

TEST_CASE("Modbus TCP requests: counts the functions do not allow are the caller's error", "[protocol][modbus]") {
    Request q = read_108_110();
    q.count = 0;
    CHECK_THROWS_AS(encoded(q), std::invalid_argument);
    q.count = 126;  // 6.3: at most 125
    CHECK_THROWS_AS(encoded(q), std::invalid_argument);
    q.count = 125;
    CHECK(encoded(q).size() == 12);
    Request w;
    w.function = kWriteMultiple;
    w.count = 3;
    w.values = {1, 2};  // fewer words than the count
    CHECK_THROWS_AS(encoded(w), std::invalid_argument);
    w.function = 0x2B;
    CHECK_THROWS_AS(encoded(w), std::invalid_argument);
}

TEST_CASE("Modbus TCP replies: the specification's answers are read, exceptions carry their code", "[protocol][modbus]") {
    const Request q = read_108_110();
    // 6.3: 03 06 022B 0000 0064: registers 108..110 hold 555, 0, 100.
    const auto r = check_reply(adu(0x0102, 0x11, {0x03, 0x06, 0x02, 0x2B, 0x00, 0x00, 0x00, 0x64}), q);
    REQUIRE(r.state == ReplyState::ok);
    CHECK(r.words == std::vector<std::uint16_t>{555, 0, 100});
    // 7: function 0x83, exception 02 (illegal data address).
    const auto e = check_reply(adu(0x0102, 0x11, {0x83, 0x02}), q);
    CHECK(e.state == ReplyState::exception);
    CHECK(e.exception_code == 2);
    // 6.6 and 6.12: a write's reply echoes the address and the value or the count.
    Request single;
    single.transaction = 9;
    single.function = kWriteSingle;
    single.address = 1;
    single.values = {3};
    CHECK(check_reply(adu(9, 1, {0x06, 0x00, 0x01, 0x00, 0x03}), single).state == ReplyState::ok);
    CHECK(check_reply(adu(9, 1, {0x06, 0x00, 0x01, 0x00, 0x04}), single).state == ReplyState::malformed);
    Request multiple = single;
    multiple.function = kWriteMultiple;
    multiple.count = 2;
    multiple.values = {0x000A, 0x0102};
    CHECK(check_reply(adu(9, 1, {0x10, 0x00, 0x01, 0x00, 0x02}), multiple).state == ReplyState::ok);
    CHECK(check_reply(adu(9, 1, {0x10, 0x00, 0x01, 0x00, 0x03}), multiple).state == ReplyState::malformed);
}

TEST_CASE("Modbus TCP replies: a reply that is not the request's answer is malformed, and says which field", "[protocol][modbus]") {
    const Request q = read_108_110();
    const std::vector<std::uint8_t> good_pdu = {0x03, 0x06, 0x02, 0x2B, 0x00, 0x00, 0x00, 0x64};
    auto malformed_because = [&](const std::vector<std::uint8_t>& bytes, const char* word) {
        const auto r = check_reply(bytes, q);
        CHECK(r.state == ReplyState::malformed);
        CHECK(r.why.find(word) != std::string::npos);
        CHECK(r.words.empty());
    };
    malformed_because(adu(0x0103, 0x11, good_pdu), "transaction");
    malformed_because(adu(0x0102, 0x12, good_pdu), "unit");
    malformed_because(adu(0x0102, 0x11, {0x04, 0x06, 0x02, 0x2B, 0x00, 0x00, 0x00, 0x64}), "function");
    // Byte count saying 4 where 3 registers were asked for, and data bytes short of the count.
    malformed_because(adu(0x0102, 0x11, {0x03, 0x04, 0x02, 0x2B, 0x00, 0x00}), "data bytes");
    malformed_because(adu(0x0102, 0x11, {0x03, 0x06, 0x02, 0x2B, 0x00, 0x00}), "data bytes");
    malformed_because(adu(0x0102, 0x11, {0x83, 0x02, 0x00}), "exception");
    auto lying_length = adu(0x0102, 0x11, good_pdu);
    lying_length[5] = 3;
    malformed_because(lying_length, "length");
    auto other_protocol = adu(0x0102, 0x11, good_pdu);
    other_protocol[3] = 1;
    malformed_because(other_protocol, "protocol");
    malformed_because({0x01, 0x02, 0x00}, "shorter");
}
