// libFuzzer target for protocol/modbus_tcp_pdu: a reply from a device, checked against the
// request the client sent. The first 8 bytes build the request (transaction, unit, function,
// address, count, written word), the rest is cut by first_frame as the client cuts what its
// socket delivers and each ADU checked as that request's reply. Checked: an answered read holds
// exactly `count` words; an answer's transaction, unit and function are the request's; nothing
// escapes.
#include <cstddef>
#include <cstdint>
#include <span>

#include "fuzz/fuzz_check.hpp"
#include "protocol/modbus_tcp_frame.hpp"
#include "protocol/modbus_tcp_pdu.hpp"

using namespace manikind::protocol::modbus_tcp;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size < 8) return 0;
    static constexpr std::uint8_t kFunctions[] = {kReadHolding, kReadInput, kWriteSingle, kWriteMultiple};
    Request q;
    q.transaction = static_cast<std::uint16_t>((data[0] << 8) | data[1]);
    q.unit = data[2];
    q.function = kFunctions[data[3] % 4];
    q.address = static_cast<std::uint16_t>((data[4] << 8) | data[5]);
    q.count = static_cast<std::uint16_t>(1 + data[6] % kMaxReadCount);
    if (q.function == kWriteSingle) q.count = 1;
    if (q.function == kWriteMultiple) q.count = static_cast<std::uint16_t>(1 + data[6] % kMaxWriteCount);
    q.values.assign(q.function == kWriteSingle || q.function == kWriteMultiple ? q.count : 0, data[7]);
    std::vector<std::uint8_t> request;
    append_request(request, q);  // a request this client can send encodes, and frames as one ADU
    FUZZ_CHECK(first_frame(request.data(), request.size()).size == request.size());
    std::size_t at = 8;
    while (at < size) {
        const Frame f = first_frame(data + at, size - at);
        if (f.state != FrameState::complete) break;
        const std::span<const std::uint8_t> adu(data + at, f.size);
        const Reply r = check_reply(adu, q);
        if (r.state != ReplyState::malformed) {
            FUZZ_CHECK(transaction_of(adu) == q.transaction && adu[6] == q.unit);
            FUZZ_CHECK((adu[7] & 0x7f) == q.function);
        }
        if (r.state == ReplyState::ok && (q.function == kReadHolding || q.function == kReadInput))
            FUZZ_CHECK(r.words.size() == q.count);
        if (r.state != ReplyState::ok) FUZZ_CHECK(r.words.empty());
        if (r.state == ReplyState::malformed) FUZZ_CHECK(!r.why.empty());
        at += f.size;
    }
    return 0;
}
