#include "protocol/modbus_tcp_pdu.hpp"

#include <stdexcept>

namespace manikind::protocol::modbus_tcp {

namespace {

void put16(std::vector<std::uint8_t>& out, unsigned v) {
    out.push_back(static_cast<std::uint8_t>((v >> 8) & 0xff));
    out.push_back(static_cast<std::uint8_t>(v & 0xff));
}

unsigned get16(std::span<const std::uint8_t> b, std::size_t at) { return (static_cast<unsigned>(b[at]) << 8) | b[at + 1]; }

Reply malformed(std::string why) {
    Reply r;
    r.state = ReplyState::malformed;
    r.why = std::move(why);
    return r;
}

}  // namespace

void append_request(std::vector<std::uint8_t>& out, const Request& q) {
    // PDU: function code and its fields (6.3, 6.4, 6.6, 6.12).
    std::vector<std::uint8_t> pdu;
    pdu.push_back(q.function);
    put16(pdu, q.address);
    switch (q.function) {
        case kReadHolding:
        case kReadInput:
            if (q.count < 1 || q.count > kMaxReadCount)
                throw std::invalid_argument("a read asks for 1.." + std::to_string(kMaxReadCount) + " registers, not " + std::to_string(q.count));
            put16(pdu, q.count);
            break;
        case kWriteSingle:
            if (q.values.size() != 1) throw std::invalid_argument("a single-register write carries one word");
            put16(pdu, q.values[0]);
            break;
        case kWriteMultiple:
            if (q.values.empty() || q.values.size() > kMaxWriteCount || q.values.size() != q.count)
                throw std::invalid_argument("a multiple write carries 1.." + std::to_string(kMaxWriteCount) + " words, as many as its count");
            put16(pdu, q.count);
            pdu.push_back(static_cast<std::uint8_t>(2 * q.count));
            for (const auto w : q.values) put16(pdu, w);
            break;
        default:
            throw std::invalid_argument("function " + std::to_string(q.function) + " is not one this client sends");
    }
    // MBAP: transaction id, protocol id 0, length (the unit id and the PDU), unit id.
    put16(out, q.transaction);
    put16(out, 0);
    put16(out, static_cast<unsigned>(pdu.size() + 1));
    out.push_back(q.unit);
    out.insert(out.end(), pdu.begin(), pdu.end());
}

Reply check_reply(std::span<const std::uint8_t> adu, const Request& q) {
    // The MBAP header and a function code at least; the length must say what the ADU holds
    // (first_frame cut it so, but this function trusts no caller with hostile bytes).
    if (adu.size() < 8) return malformed(std::to_string(adu.size()) + " bytes, shorter than a header and a function code");
    if (get16(adu, 2) != 0) return malformed("protocol id " + std::to_string(get16(adu, 2)) + ", not 0");
    if (get16(adu, 4) + 6 != adu.size())
        return malformed("length field " + std::to_string(get16(adu, 4)) + " for " + std::to_string(adu.size()) + " bytes");
    if (transaction_of(adu) != q.transaction)
        return malformed("transaction " + std::to_string(transaction_of(adu)) + " answers none sent (expected " + std::to_string(q.transaction) + ")");
    if (adu[6] != q.unit) return malformed("unit " + std::to_string(adu[6]) + " answers a request to unit " + std::to_string(q.unit));
    const std::uint8_t function = adu[7];
    if (function == (q.function | 0x80)) {  // 7: an exception response carries one code
        if (adu.size() != 9) return malformed("exception response of " + std::to_string(adu.size()) + " bytes, not 9");
        Reply r;
        r.state = ReplyState::exception;
        r.exception_code = adu[8];
        return r;
    }
    if (function != q.function) return malformed("function " + std::to_string(function) + " answers function " + std::to_string(q.function));
    Reply r;
    r.state = ReplyState::ok;
    switch (q.function) {
        case kReadHolding:
        case kReadInput: {
            const std::size_t want = 2 * static_cast<std::size_t>(q.count);
            if (adu.size() < 9 || adu[8] != want || adu.size() != 9 + want)
                return malformed(std::to_string(adu.size() < 9 ? 0 : adu[8]) + " data bytes in " + std::to_string(adu.size()) +
                                 " for " + std::to_string(q.count) + " registers");
            r.words.reserve(q.count);
            for (std::size_t i = 0; i < q.count; ++i) r.words.push_back(static_cast<std::uint16_t>(get16(adu, 9 + 2 * i)));
            return r;
        }
        case kWriteSingle:
            if (adu.size() != 12 || get16(adu, 8) != q.address || q.values.empty() || get16(adu, 10) != q.values[0])
                return malformed("the write's echo differs from the request");
            return r;
        case kWriteMultiple:
            if (adu.size() != 12 || get16(adu, 8) != q.address || get16(adu, 10) != q.count)
                return malformed("the write's echo differs from the request");
            return r;
        default:
            return malformed("function " + std::to_string(q.function) + " is not one this client sends");
    }
}

}  // namespace manikind::protocol::modbus_tcp
