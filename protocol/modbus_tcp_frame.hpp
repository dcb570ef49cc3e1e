#pragma once
// Modbus TCP framing (Modbus Messaging on TCP/IP Implementation Guide V1.0b, 3.1.3): an ADU is
// the 7-byte MBAP header (transaction id, protocol id 0, length, unit id) and the PDU; `length`
// counts the unit id and the PDU, so a whole ADU is 6 + length bytes, at most 260 (a PDU is at
// most 253 bytes, Modbus Application Protocol V1.1b3, 4.1). A stream of bytes from a socket is
// cut into ADUs here, so a server can read whatever arrived in one call instead of asking for
// the header and the rest separately (libmodbus's receive waits in select before each part).
// Pure: no I/O. Every byte is hostile: a length outside 2..254 or a protocol id other than 0 is
// malformed (a device closes such a connection).
#include <cstddef>
#include <cstdint>

namespace manikind::protocol::modbus_tcp {

inline constexpr std::size_t kHeaderBytes = 7;   // MBAP, the unit id included
inline constexpr std::size_t kMaxAduBytes = 260;

enum class FrameState { need_more, complete, malformed };

struct Frame {
    FrameState state = FrameState::need_more;
    std::size_t size = 0;  // complete: the ADU's bytes from the start of the buffer
};

// The first ADU in `bytes[0..n)`: complete (with its size), not yet whole, or malformed.
inline Frame first_frame(const std::uint8_t* bytes, std::size_t n) {
    // Decided as early as the bytes allow: protocol id at 4 bytes, the length at 6.
    if (n >= 4 && (bytes[2] != 0 || bytes[3] != 0)) return {FrameState::malformed, 0};
    if (n < 6) return {FrameState::need_more, 0};
    const std::size_t length = (static_cast<std::size_t>(bytes[4]) << 8) | bytes[5];  // unit id + PDU
    if (length < 2 || length > kMaxAduBytes - 6) return {FrameState::malformed, 0};  // a PDU holds a function code at least
    const std::size_t size = 6 + length;
    if (n < size) return {FrameState::need_more, 0};
    return {FrameState::complete, size};
}

}  // namespace manikind::protocol::modbus_tcp
