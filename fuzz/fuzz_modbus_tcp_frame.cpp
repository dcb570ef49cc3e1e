// libFuzzer target for protocol/modbus_tcp_frame: any bytes from a socket are cut into Modbus TCP
// ADUs as the simulated device's server does. Checked: a complete ADU is 8..260 bytes and within
// the input; what a prefix decided (complete with a size, or malformed) the whole input decides
// alike, so bytes arriving later never change where a request ended.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_check.hpp"
#include "protocol/modbus_tcp_frame.hpp"

using namespace manikind::protocol::modbus_tcp;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::size_t at = 0;
    while (at < size) {
        const Frame whole = first_frame(data + at, size - at);
        if (whole.state == FrameState::complete) {
            FUZZ_CHECK(whole.size >= 8 && whole.size <= kMaxAduBytes && whole.size <= size - at);
        }
        for (std::size_t k = 0; k <= size - at && k <= kMaxAduBytes + 1; ++k) {
            const Frame part = first_frame(data + at, k);
            if (part.state == FrameState::complete) FUZZ_CHECK(whole.state == FrameState::complete && whole.size == part.size);
            if (part.state == FrameState::malformed) FUZZ_CHECK(whole.state == FrameState::malformed);
        }
        if (whole.state != FrameState::complete) break;
        at += whole.size;
    }
    return 0;
}
