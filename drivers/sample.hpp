#pragma once
// What every driver produces: one timestamped, quality-flagged value of one channel. The
// acquisition bus carries these to the recorder and the live status (DESIGN.md, data flow).
#include <cstdint>
#include <functional>
#include <string>

namespace manikind::drivers {

// Stored as an integer in the recorder (samples.quality); keep the numbers stable.
enum class Quality : std::uint8_t {
    good = 0,
    stale = 1,          // the device stopped updating; the value is the last one seen
    out_of_range = 2,   // decoded, but outside the channel's physical range or flagged by the device
    comm_error = 3,     // the read failed (timeout, checksum, exception, disconnected)
};
const char* to_string(Quality q);

// The unit a channel's name carries in its suffix (names say their unit: skin_temp_c,
// air_rh_pct, air_speed_m_s, heat_flux_w_m2, sweat_rate_g_m2_h); the suffix itself otherwise.
std::string unit_of_channel(const std::string& channel);

struct Sample {
    std::string device;      // "windsonic", "manikin", "chamber", "datalogger"
    std::string channel;     // "air_speed_m_s", "z05.skin_temp_c", ...
    double value = 0.0;
    Quality quality = Quality::good;
    std::int64_t mono_ns = 0;  // monotonic (or virtual) clock
    std::int64_t utc_ns = 0;   // wall-clock UTC
};

using SampleSink = std::function<void(const Sample&)>;

}  // namespace manikind::drivers
