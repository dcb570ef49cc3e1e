#include "protocol/manikin_can.hpp"

#include <linux/can/error.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "protocol/fixed_point.hpp"

namespace manikind::protocol::manikin_can {
namespace {

void put_u16(std::uint8_t* p, std::uint16_t v) {
    p[0] = static_cast<std::uint8_t>(v & 0xff);
    p[1] = static_cast<std::uint8_t>(v >> 8);
}
std::uint16_t get_u16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }

// Scaled integer with saturation: values beyond the field's range are clamped, never wrapped.
std::int16_t to_i16(double value, double scale) {
    const double raw = std::round(value / scale);
    if (!(raw == raw)) return 0;
    return static_cast<std::int16_t>(std::fmax(-32768.0, std::fmin(32767.0, raw)));
}
std::uint16_t to_u16(double value, double scale) {
    const double raw = std::round(value / scale);
    if (!(raw == raw)) return 0;
    return static_cast<std::uint16_t>(std::fmax(0.0, std::fmin(65535.0, raw)));
}

can_frame frame_with(canid_t id, std::uint8_t dlc) {
    can_frame f;
    std::memset(&f, 0, sizeof f);
    f.can_id = id;
    f.can_dlc = dlc;
    return f;
}

bool valid_mode(std::uint8_t m) { return m <= 2; }

}  // namespace

can_frame encode(const ZoneStatus& m) {
    can_frame f = frame_with(id_zone_status_base + static_cast<canid_t>(m.zone), 8);
    put_u16(f.data + 0, static_cast<std::uint16_t>(to_i16(m.skin_temp_c, 0.01)));
    put_u16(f.data + 2, static_cast<std::uint16_t>(to_i16(m.heat_flux_w_m2, 0.1)));
    put_u16(f.data + 4, to_u16(m.heater_power_w_m2, 0.1));
    f.data[6] = static_cast<std::uint8_t>(std::fmin(255.0, std::fmax(0.0, std::round(m.sweat_rate_g_m2_h / 2.0))));
    f.data[7] = m.flags;
    return f;
}

can_frame encode(const Heartbeat& m) {
    can_frame f = frame_with(id_heartbeat, 6);
    f.data[0] = static_cast<std::uint8_t>(m.mode);
    f.data[1] = m.sequence;
    put_u16(f.data + 2, m.error_bits);
    put_u16(f.data + 4, to_u16(m.shell_supply_v, 0.01));
    return f;
}

can_frame encode(const Setpoint& m) {
    can_frame f = frame_with(id_setpoint_base + static_cast<canid_t>(m.zone), 6);
    f.data[0] = static_cast<std::uint8_t>(m.mode);
    const double scale = m.mode == ControlMode::constant_heat_flux ? 0.1 : 0.01;
    put_u16(f.data + 1, static_cast<std::uint16_t>(to_i16(m.value, scale)));
    f.data[3] = m.sweating ? 1 : 0;
    put_u16(f.data + 4, to_u16(m.sweat_rate_g_m2_h, 0.1));
    return f;
}

can_frame encode(const Control& m) {
    can_frame f = frame_with(id_control, 2);
    f.data[0] = m.run ? 1 : 0;
    f.data[1] = m.heartbeat;
    return f;
}

std::variant<Message, DecodeError> decode(const can_frame& f) {
    if (f.can_id & CAN_ERR_FLAG) {
        BusError e;
        e.error_class = f.can_id & CAN_ERR_MASK;
        e.bus_off = (f.can_id & CAN_ERR_BUSOFF) != 0;
        return Message{e};
    }
    if (f.can_id & CAN_RTR_FLAG) return DecodeError{"remote (RTR) frames are not used on this bus"};
    if (f.can_id & CAN_EFF_FLAG) return DecodeError{"extended (29-bit) identifiers are not used on this bus"};
    if (f.can_dlc > 8) return DecodeError{"DLC above 8"};
    const canid_t id = f.can_id & CAN_SFF_MASK;
    auto need = [&](std::uint8_t dlc) { return f.can_dlc == dlc; };
    if (id == id_heartbeat) {
        if (!need(6)) return DecodeError{"heartbeat needs 6 bytes"};
        if (!valid_mode(f.data[0])) return DecodeError{"heartbeat: unknown control mode"};
        return Message{Heartbeat{static_cast<ControlMode>(f.data[0]), f.data[1], get_u16(f.data + 2), scaled_value(get_u16(f.data + 4), 0.01)}};
    }
    if (id > id_zone_status_base && id <= id_zone_status_base + zone_count) {
        if (!need(8)) return DecodeError{"zone status needs 8 bytes"};
        ZoneStatus z;
        z.zone = static_cast<int>(id - id_zone_status_base);
        z.skin_temp_c = scaled_value(static_cast<std::int16_t>(get_u16(f.data + 0)), 0.01);
        z.heat_flux_w_m2 = scaled_value(static_cast<std::int16_t>(get_u16(f.data + 2)), 0.1);
        z.heater_power_w_m2 = scaled_value(get_u16(f.data + 4), 0.1);
        z.sweat_rate_g_m2_h = f.data[6] * 2.0;
        z.flags = f.data[7];
        return Message{z};
    }
    if (id >= id_setpoint_base && id <= id_setpoint_base + zone_count) {
        if (!need(6)) return DecodeError{"setpoint needs 6 bytes"};
        if (!valid_mode(f.data[0])) return DecodeError{"setpoint: unknown control mode"};
        Setpoint s;
        s.zone = static_cast<int>(id - id_setpoint_base);
        s.mode = static_cast<ControlMode>(f.data[0]);
        s.value = scaled_value(static_cast<std::int16_t>(get_u16(f.data + 1)), s.mode == ControlMode::constant_heat_flux ? 0.1 : 0.01);
        s.sweating = f.data[3] != 0;
        s.sweat_rate_g_m2_h = scaled_value(get_u16(f.data + 4), 0.1);
        return Message{s};
    }
    if (id == id_control) {
        if (!need(2)) return DecodeError{"control needs 2 bytes"};
        return Message{Control{f.data[0] != 0, f.data[1]}};
    }
    char buf[64];
    std::snprintf(buf, sizeof buf, "unknown identifier 0x%03X", static_cast<unsigned>(id));
    return DecodeError{buf};
}

std::string to_candump_line(const can_frame& f, double utc_s, const std::string& interface) {
    char head[64];
    std::snprintf(head, sizeof head, "(%.6f) %s ", utc_s, interface.c_str());
    std::string out = head;
    char id[16];
    // candump -l: 3 hex digits for standard ids, 8 for extended ones and for error frames
    // (which carry CAN_ERR_FLAG, 0x20000000, in the printed id).
    if (f.can_id & CAN_ERR_FLAG) std::snprintf(id, sizeof id, "%08X#", f.can_id & (CAN_ERR_MASK | CAN_ERR_FLAG));
    else if (f.can_id & CAN_EFF_FLAG) std::snprintf(id, sizeof id, "%08X#", f.can_id & CAN_EFF_MASK);
    else std::snprintf(id, sizeof id, "%03X#", f.can_id & CAN_SFF_MASK);
    out += id;
    for (int i = 0; i < f.can_dlc && i < 8; ++i) {
        char b[4];
        std::snprintf(b, sizeof b, "%02X", f.data[i]);
        out += b;
    }
    return out;
}

std::optional<std::pair<double, can_frame>> parse_candump_line(const std::string& line) {
    // (seconds.micro) iface ID#DATA
    if (line.size() < 10 || line[0] != '(') return std::nullopt;
    const auto close = line.find(')');
    if (close == std::string::npos) return std::nullopt;
    double t = 0.0;
    {
        const auto [p, ec] = std::from_chars(line.data() + 1, line.data() + close, t);
        if (ec != std::errc() || p != line.data() + close) return std::nullopt;
    }
    const auto space = line.find(' ', close + 2);
    if (space == std::string::npos) return std::nullopt;
    const auto hash = line.find('#', space);
    if (hash == std::string::npos) return std::nullopt;
    const std::string_view id_text(line.data() + space + 1, hash - space - 1);
    std::uint32_t id = 0;
    {
        const auto [p, ec] = std::from_chars(id_text.data(), id_text.data() + id_text.size(), id, 16);
        if (ec != std::errc() || p != id_text.data() + id_text.size()) return std::nullopt;
    }
    if (id_text.size() != 3 && id_text.size() != 8) return std::nullopt;
    const canid_t can_id = id_text.size() == 3 ? id : (id & CAN_ERR_FLAG) ? id : (id | CAN_EFF_FLAG);
    can_frame f = frame_with(can_id, 0);
    std::string_view data(line.data() + hash + 1, line.size() - hash - 1);
    while (!data.empty() && (data.back() == '\r' || data.back() == '\n' || data.back() == ' ')) data.remove_suffix(1);
    if (data.size() % 2 != 0 || data.size() > 16) return std::nullopt;
    for (std::size_t i = 0; i < data.size(); i += 2) {
        unsigned v = 0;
        const auto [p, ec] = std::from_chars(data.data() + i, data.data() + i + 2, v, 16);
        if (ec != std::errc() || p != data.data() + i + 2) return std::nullopt;
        f.data[i / 2] = static_cast<std::uint8_t>(v);
    }
    f.can_dlc = static_cast<std::uint8_t>(data.size() / 2);
    return std::make_pair(t, f);
}

CandumpLogLine parse_candump_log_line(const std::string& line) {
    CandumpLogLine out;
    const auto parsed = parse_candump_line(line);
    if (!parsed) {
        out.error = "not a candump -l line (expected \"(seconds.micro) can0 ID#HEX\")";
        return out;
    }
    const double t_s = parsed->first;
    // from_chars reads "inf", "nan" and 1e300 too: converting those to an integer is undefined.
    if (!std::isfinite(t_s) || t_s < 0.0 || t_s >= kMaxCandumpStamp_s) {
        char text[160];
        std::snprintf(text, sizeof text, "time stamp %g s is not a time: it must be finite, 0 or more and below %g s", t_s,
                      kMaxCandumpStamp_s);
        out.error = text;
        return out;
    }
    out.utc_ns = static_cast<std::int64_t>(std::llround(t_s * 1e9));
    out.frame = parsed->second;
    return out;
}

}  // namespace manikind::protocol::manikin_can
