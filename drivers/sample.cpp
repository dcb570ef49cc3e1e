#include "drivers/sample.hpp"

namespace manikind::drivers {

const char* to_string(Quality q) {
    switch (q) {
        case Quality::good: return "good";
        case Quality::stale: return "stale";
        case Quality::out_of_range: return "out_of_range";
        case Quality::comm_error: return "comm_error";
    }
    return "unknown";
}

}  // namespace manikind::drivers
