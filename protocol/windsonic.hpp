#pragma once
// Gill WindSonic ASCII output (WindSonic user manual, Doc No 1405 PS 0019, section 9 "Message
// formats"): <STX>Q,229,002.74,M,00,<ETX>16<CR><LF>, the checksum being the XOR of the bytes
// between (not including) STX and ETX, in two hex digits. Gill polar and UV formats, continuous
// or polled (same frame). A byte-at-a-time parser that survives partial reads and garbage.
// Pure: no I/O, no clocks.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace manikind::protocol::windsonic {

// Status codes (manual section 11.5): 00 OK; 01 axis 1 failed; 02 axis 2 failed; 04 both
// axes failed; 08 NVM checksum failed; 09 ROM checksum failed; 51 measurement average building.
const char* status_text(int status_code);
bool status_ok(int status_code);

enum class Format { polar, uv };

struct Reading {
    char node = 'Q';                  // node address (unit identifier)
    Format format = Format::polar;
    std::optional<int> direction_deg; // polar; absent when the speed is too low for a direction
    double speed = 0.0;               // polar: wind speed, in `units`
    double u = 0.0, v = 0.0;          // UV format, in `units`
    char units = 'M';                 // M m/s, N knots, P mph, K km/h, F ft/min
    int status = 0;
    double speed_m_s() const;         // speed (polar) or |(u, v)| (UV) converted to m/s
};

// The frame's payload (between STX and ETX) and the full frame with checksum and CR LF.
std::string encode_payload(const Reading& r);
std::string encode_frame(const Reading& r);
std::uint8_t checksum(std::string_view payload);

// Parses a payload such as "Q,229,002.74,M,00,". Empty result on any malformed field.
std::optional<Reading> parse_payload(std::string_view payload);

// Incremental parser: feed bytes as they arrive; each complete, valid frame yields a Reading.
class Parser {
public:
    enum class Event { none, reading, checksum_error, malformed };
    struct Counters {
        std::uint64_t frames = 0, checksum_errors = 0, malformed = 0, bytes_discarded = 0;
    };

    Event feed(std::uint8_t byte);
    const Reading& reading() const { return reading_; }
    const Counters& counters() const { return counters_; }

private:
    enum class State { unsynced, payload, checksum_hi, checksum_lo };
    State state_ = State::unsynced;
    std::string payload_;
    std::uint8_t received_checksum_ = 0;
    Reading reading_;
    Counters counters_;
    static constexpr std::size_t max_payload = 64;  // real frames are ~20-40 bytes
};

}  // namespace manikind::protocol::windsonic
