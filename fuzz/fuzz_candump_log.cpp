// libFuzzer target for the capture `manikin replay` reads: the input split into lines the way
// the command does (blank and '#' lines skipped), each through parse_candump_log_line, the very
// check `manikin replay` runs. A line that parses must give a valid frame and a stamp of 0 or
// more that survives write + parse to the microsecond; one that does not must say why.
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
        if (!parsed.ok()) {
            FUZZ_CHECK(!parsed.error.empty());
            continue;
        }
        FUZZ_CHECK(parsed.frame.can_dlc <= 8);
        FUZZ_CHECK(parsed.utc_ns >= 0);
        // Near the limit, printing to the microsecond may round past it: nothing to compare.
        if (parsed.utc_ns > 9'000'000'000'000'000'000) continue;
        const auto again = parse_candump_log_line(to_candump_line(parsed.frame, static_cast<double>(parsed.utc_ns) * 1e-9));
        FUZZ_CHECK(again.ok());
        FUZZ_CHECK(std::llabs(again.utc_ns - parsed.utc_ns) <= 1'000'000);  // printed to the µs; doubles near 1e18 ns are µs-coarse
    }
    return 0;
}
