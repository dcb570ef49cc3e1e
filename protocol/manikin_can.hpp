#pragma once
// The 35-zone manikin's CAN bus: our own documented layout (the vendor's bus is proprietary;
// see docs/manikin-can-bus.md). Classic CAN, 11-bit identifiers, little-endian payloads,
// struct can_frame as SocketCAN carries it (on can0, or one end of a SOCK_SEQPACKET socketpair).
// Pure: frames in, typed values out.
#include <linux/can.h>

#include <cstdint>
#include <optional>
#include <string>
#include <variant>

namespace manikind::protocol::manikin_can {

inline constexpr int zone_count = 35;

// Identifiers.
inline constexpr canid_t id_heartbeat = 0x080;       // manikin -> host, every 100 ms
inline constexpr canid_t id_zone_status_base = 0x100; // + zone (1..35): manikin -> host
inline constexpr canid_t id_setpoint_base = 0x200;    // + zone (1..35), or +0 for all zones: host -> manikin
inline constexpr canid_t id_control = 0x280;          // host -> manikin: run/stop, heartbeat echo

enum class ControlMode : std::uint8_t { idle = 0, constant_skin_temp = 1, constant_heat_flux = 2 };

// Zone status flags (byte 7 of a zone status frame).
enum ZoneFlag : std::uint8_t {
    heater_on = 1u << 0,
    sweating_on = 1u << 1,
    sensor_fault = 1u << 2,
    heater_fault = 1u << 3,
    over_temperature = 1u << 4,
};

struct ZoneStatus {
    int zone = 1;                  // 1..35
    double skin_temp_c = 0.0;      // int16, 0.01 °C
    double heat_flux_w_m2 = 0.0;   // int16, 0.1 W/m², positive = heat lost
    double heater_power_w_m2 = 0.0;// uint16, 0.1 W/m²
    double sweat_rate_g_m2_h = 0.0;// uint8, 2 g/(m² h) per count (0..510)
    std::uint8_t flags = 0;
};

struct Heartbeat {
    ControlMode mode = ControlMode::idle;
    std::uint8_t sequence = 0;     // increments per heartbeat; a gap means lost frames
    std::uint16_t error_bits = 0;  // bit 0 watchdog tripped, bit 1 supply fault, bit 2 coolant fault
    double shell_supply_v = 0.0;   // uint16, 0.01 V
};

struct Setpoint {
    int zone = 0;                  // 0 = all zones
    ControlMode mode = ControlMode::constant_skin_temp;
    double value = 35.0;           // °C (skin mode, 0.01 °C) or W/m² (flux mode, 0.1 W/m²)
    bool sweating = false;
    double sweat_rate_g_m2_h = 0.0;// uint16, 0.1 g/(m² h)
};

struct Control {
    bool run = false;
    std::uint8_t heartbeat = 0;    // echoed host counter; the manikin stops heating when it stalls
};

struct BusError {
    std::uint32_t error_class = 0; // CAN_ERR_* bits from the id
    bool bus_off = false;
};

using Message = std::variant<ZoneStatus, Heartbeat, Setpoint, Control, BusError>;

struct DecodeError {
    std::string reason;
};

can_frame encode(const ZoneStatus& m);
can_frame encode(const Heartbeat& m);
can_frame encode(const Setpoint& m);
can_frame encode(const Control& m);

// Decodes any frame of the layout; a wrong length, unknown id, zone out of range or an RTR
// frame gives a DecodeError with the reason. Error frames (CAN_ERR_FLAG) decode to BusError.
std::variant<Message, DecodeError> decode(const can_frame& frame);

// can-utils `candump -l` log line: "(1718000000.123456) can0 123#11223344".
std::string to_candump_line(const can_frame& frame, double utc_s, const std::string& interface = "can0");
std::optional<std::pair<double, can_frame>> parse_candump_line(const std::string& line);
// The same line as `manikin replay` stores it: its time in UTC nanoseconds, rounded. The one
// check of a capture's stamps (the fuzz target fuzz_candump_log runs exactly this): the time
// must be finite, 0 or more and below kMaxCandumpStamp_s (int64 nanoseconds end in 2262).
// On failure `error` says what is wrong with the line, for a message naming file and line.
inline constexpr double kMaxCandumpStamp_s = 9.2e9;
struct CandumpLogLine {
    std::int64_t utc_ns = 0;
    can_frame frame{};
    std::string error;  // empty when the line is good
    bool ok() const { return error.empty(); }
};
CandumpLogLine parse_candump_log_line(const std::string& line);

}  // namespace manikind::protocol::manikin_can
