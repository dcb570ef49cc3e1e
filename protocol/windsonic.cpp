#include "protocol/windsonic.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <vector>

namespace manikind::protocol::windsonic {
namespace {

constexpr char stx = 0x02;
constexpr char etx = 0x03;

std::vector<std::string_view> split_fields(std::string_view s) {
    std::vector<std::string_view> out;
    std::size_t start = 0;
    for (std::size_t i = 0; i <= s.size(); ++i)
        if (i == s.size() || s[i] == ',') {
            std::string_view f = s.substr(start, i - start);
            while (!f.empty() && f.front() == ' ') f.remove_prefix(1);  // the manual prints "Q, 229, ..."
            while (!f.empty() && f.back() == ' ') f.remove_suffix(1);
            out.push_back(f);
            start = i + 1;
        }
    return out;
}

std::optional<double> to_double(std::string_view f) {
    if (f.empty()) return std::nullopt;
    if (f.front() == '+') f.remove_prefix(1);
    double v = 0.0;
    const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), v);
    if (ec != std::errc() || ptr != f.data() + f.size() || !std::isfinite(v)) return std::nullopt;
    return v;
}

std::optional<int> to_int(std::string_view f, int base = 10) {
    if (f.empty()) return std::nullopt;
    int v = 0;
    const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), v, base);
    if (ec != std::errc() || ptr != f.data() + f.size()) return std::nullopt;
    return v;
}

int hex_digit(std::uint8_t c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

double to_m_s(double value, char units) {
    switch (units) {
        case 'M': return value;
        case 'N': return value * 0.514444;   // knot
        case 'P': return value * 0.44704;    // mile per hour
        case 'K': return value / 3.6;        // km/h
        case 'F': return value * 0.00508;    // ft/min
        default: return NAN;
    }
}

}  // namespace

const char* status_text(int s) {
    switch (s) {
        case 0: return "OK";
        case 1: return "axis 1 failed";
        case 2: return "axis 2 failed";
        case 4: return "axis 1 and 2 failed";
        case 8: return "NVM checksum failed";
        case 9: return "ROM checksum failed";
        case 0x51: return "measurement average building";
        default: return "unknown status";
    }
}

bool status_ok(int s) { return s == 0; }

double Reading::speed_m_s() const {
    return to_m_s(format == Format::polar ? speed : std::hypot(u, v), units);
}

std::uint8_t checksum(std::string_view payload) {
    std::uint8_t x = 0;
    for (char c : payload) x = static_cast<std::uint8_t>(x ^ static_cast<std::uint8_t>(c));
    return x;
}

std::string encode_payload(const Reading& r) {
    char buf[96];
    if (r.format == Format::polar) {
        const std::string dir = r.direction_deg ? [&] { char d[8]; std::snprintf(d, sizeof d, "%03d", *r.direction_deg); return std::string(d); }() : std::string();
        std::snprintf(buf, sizeof buf, "%c,%s,%06.2f,%c,%02X,", r.node, dir.c_str(), r.speed, r.units, r.status);
    } else {
        std::snprintf(buf, sizeof buf, "%c,%+07.2f,%+07.2f,%c,%02X,", r.node, r.u, r.v, r.units, r.status);
    }
    return buf;
}

std::string encode_frame(const Reading& r) {
    const std::string payload = encode_payload(r);
    char tail[8];
    std::snprintf(tail, sizeof tail, "%02X\r\n", checksum(payload));
    return std::string(1, stx) + payload + std::string(1, etx) + tail;
}

std::optional<Reading> parse_payload(std::string_view payload) {
    auto f = split_fields(payload);
    if (!f.empty() && f.back().empty()) f.pop_back();  // the trailing comma before ETX
    if (f.size() != 5 || f[0].size() != 1 || f[3].size() != 1) return std::nullopt;
    Reading r;
    r.node = f[0][0];
    r.units = f[3][0];
    if (std::string_view("MNPKF").find(r.units) == std::string_view::npos) return std::nullopt;
    // The status field is two hex digits (51 = average building is printed as "51").
    const auto status = to_int(f[4], 16);
    if (!status || f[4].size() != 2) return std::nullopt;
    r.status = *status;
    const bool uv = !f[1].empty() && (f[1].front() == '+' || f[1].front() == '-');
    if (uv) {
        const auto u = to_double(f[1]), v = to_double(f[2]);
        if (!u || !v) return std::nullopt;
        r.format = Format::uv;
        r.u = *u;
        r.v = *v;
    } else {
        const auto speed = to_double(f[2]);
        if (!speed || *speed < 0.0) return std::nullopt;
        r.speed = *speed;
        if (!f[1].empty()) {
            const auto dir = to_int(f[1]);
            if (!dir || *dir < 0 || *dir > 359) return std::nullopt;
            r.direction_deg = *dir;
        }
    }
    return r;
}

Parser::Event Parser::feed(std::uint8_t byte) {
    switch (state_) {
        case State::unsynced:
            if (byte == stx) {
                payload_.clear();
                state_ = State::payload;
            } else {
                ++counters_.bytes_discarded;
            }
            return Event::none;
        case State::payload:
            if (byte == etx) {
                state_ = State::checksum_hi;
            } else if (byte == stx) {  // a new frame started: the old one was cut short
                counters_.bytes_discarded += payload_.size();
                payload_.clear();
            } else if (payload_.size() >= max_payload || byte < 0x20 || byte > 0x7e) {
                counters_.bytes_discarded += payload_.size() + 1;
                ++counters_.malformed;
                state_ = State::unsynced;
                return Event::malformed;
            } else {
                payload_.push_back(static_cast<char>(byte));
            }
            return Event::none;
        case State::checksum_hi: {
            const int d = hex_digit(byte);
            if (d < 0) {
                ++counters_.malformed;
                state_ = byte == stx ? State::payload : State::unsynced;
                payload_.clear();
                return Event::malformed;
            }
            received_checksum_ = static_cast<std::uint8_t>(d << 4);
            state_ = State::checksum_lo;
            return Event::none;
        }
        case State::checksum_lo: {
            const int d = hex_digit(byte);
            state_ = State::unsynced;
            if (d < 0) {
                ++counters_.malformed;
                return Event::malformed;
            }
            received_checksum_ = static_cast<std::uint8_t>(received_checksum_ | d);
            if (received_checksum_ != checksum(payload_)) {
                ++counters_.checksum_errors;
                return Event::checksum_error;
            }
            const auto r = parse_payload(payload_);
            if (!r) {
                ++counters_.malformed;
                return Event::malformed;
            }
            reading_ = *r;
            ++counters_.frames;
            return Event::reading;
        }
    }
    return Event::none;
}

}  // namespace manikind::protocol::windsonic
