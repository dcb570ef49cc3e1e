#pragma once
// The client's side of Modbus TCP: requests encoded, replies checked against the request they
// answer (Modbus Application Protocol V1.1b3, 6.3 read holding registers, 6.4 read input
// registers, 6.6 write single register, 6.12 write multiple registers, 7 exception responses;
// MBAP header: Modbus Messaging on TCP/IP Implementation Guide V1.0b, 3.1.3). Pure: no I/O. A
// reply is hostile until checked: its transaction id, unit id, function code, byte count and
// echoed fields must all be the ones the request asked for, or it is malformed.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace manikind::protocol::modbus_tcp {

inline constexpr std::uint8_t kReadHolding = 0x03;
inline constexpr std::uint8_t kReadInput = 0x04;
inline constexpr std::uint8_t kWriteSingle = 0x06;
inline constexpr std::uint8_t kWriteMultiple = 0x10;
inline constexpr int kMaxReadCount = 125;   // 6.3: 1..125 registers per read
inline constexpr int kMaxWriteCount = 123;  // 6.12: 1..123 registers per write

// One request as the client sent it: what its reply must echo.
struct Request {
    std::uint16_t transaction = 0;
    std::uint8_t unit = 1;
    std::uint8_t function = kReadHolding;
    std::uint16_t address = 0;
    std::uint16_t count = 1;              // registers read, or written
    std::vector<std::uint16_t> values;    // write: the registers' new words (count of them)
};

// Appends the request's ADU (MBAP header + PDU) to `out`. Throws std::invalid_argument for a
// count the function does not allow (a caller's mistake, never a device's).
void append_request(std::vector<std::uint8_t>& out, const Request& request);

enum class ReplyState { ok, exception, malformed };

struct Reply {
    ReplyState state = ReplyState::malformed;
    std::uint8_t exception_code = 0;      // exception: 1 illegal function, 2 illegal data address, ...
    std::vector<std::uint16_t> words;     // ok, a read: the registers, `count` of them
    std::string why;                      // malformed: which field was wrong
};

// The transaction id of a whole ADU (at least 2 bytes; what first_frame cut).
inline std::uint16_t transaction_of(std::span<const std::uint8_t> adu) {
    return static_cast<std::uint16_t>((adu[0] << 8) | adu[1]);
}

// Checks one whole ADU (as cut by first_frame) as the reply to `request`.
Reply check_reply(std::span<const std::uint8_t> adu, const Request& request);

}  // namespace manikind::protocol::modbus_tcp
