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

std::string unit_of_channel(const std::string& channel) {
    const auto us = channel.rfind('_');
    const std::string suffix = us == std::string::npos ? "" : channel.substr(us + 1);
    if (suffix == "c") return "°C";
    if (suffix == "pct") return "%";
    if (suffix == "s" && channel.ends_with("_m_s")) return "m/s";
    if (suffix == "m2" && channel.ends_with("_w_m2")) return "W/m²";
    if (suffix == "h" && channel.ends_with("_g_m2_h")) return "g/(m² h)";
    return suffix;
}

}  // namespace manikind::drivers
