// libFuzzer target for the capture `manikin replay` reads: the input split into lines the way
// the command does (blank and '#' lines skipped), each through parse_candump_log_line. A line
// that parses must give a valid frame, and its time must survive write + parse to the microsecond.
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "protocol/manikin_can.hpp"
#include "fuzz/fuzz_check.hpp"

using namespace manikind::protocol::manikin_can;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
    std::string line;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#') continue;
        const auto parsed = parse_candump_log_line(line);
        if (!parsed) continue;
        const auto& [utc_ns, frame] = *parsed;
        FUZZ_CHECK(frame.can_dlc <= 8);
        // Near the limit, printing to the microsecond may round past it: nothing to compare.
        if (std::llabs(utc_ns) > 9'000'000'000'000'000'000) continue;
        const auto again = parse_candump_log_line(to_candump_line(frame, static_cast<double>(utc_ns) * 1e-9));
        FUZZ_CHECK(again.has_value());
        FUZZ_CHECK(std::llabs(again->first - utc_ns) <= 1'000'000);  // printed to the µs; doubles near 1e18 ns are µs-coarse
    }
    return 0;
}
