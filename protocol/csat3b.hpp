#pragma once
// Campbell Scientific CSAT3B 3-D sonic anemometer, unprompted ASCII output over RS-485 or USB
// (operating modes 2 and 3). CSAT3B Product Manual, section 8.3.3 "Data Output" (p. 55):
//   Ux,Uy,Uz,Ts,DiagWord,RecordCounter,Signature<terminator>
//   0.08945,0.06552,0.05726,19.69336,0,5,c3a6
// Ux/Uy/Uz in m/s, Ts sonic temperature in °C, diagnostic word (section 8.4.2, Table 8-5),
// record counter 0..63 (wraps), signature: 4 hex digits. A byte-at-a-time parser that
// survives partial reads and garbage. Pure: no I/O, no clocks.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace manikind::protocol::csat3b {

// Diagnostic word flags (manual section 8.4.2, Table 8-5).
enum DiagFlag : std::uint32_t {
    low_amplitude = 1u << 0,     // signal amplitude too low
    high_amplitude = 1u << 1,    // signal amplitude too high
    tracking = 1u << 2,          // poor signal lock
    high_delta_c = 1u << 3,      // speed-of-sound difference between axes > 2.360 m/s
    acquiring = 1u << 4,         // acquiring signals (after power-up or a lost lock)
    low_voltage = 1u << 5,       // supply below 9 V
    trigger_error = 1u << 6,
    internal_humidity = 1u << 7, // internal humidity above 80 %
    memory_error = 1u << 8,
};
inline constexpr std::uint32_t known_diag_flags = 0x1FFu;

// "ok" for 0, otherwise the flag names joined by ',' (e.g. "low_amplitude,low_voltage");
// bits outside Table 8-5 appear as "unknown_bits_0x...".
std::string diag_text(std::uint32_t diag);

struct Record {
    double ux_m_s = 0.0, uy_m_s = 0.0, uz_m_s = 0.0;  // quiet NaN when the sensor printed "NaN"
    double sonic_temp_c = 0.0;
    std::uint32_t diag = 0;        // DiagFlag bits
    int counter = 0;               // 0..63
    std::uint16_t signature = 0;   // as received (parse) or as computed (encode)

    bool diag_ok() const { return diag == 0; }
    double horizontal_speed_m_s() const;  // |(ux, uy)|
    double speed_m_s() const;             // |(ux, uy, uz)|
};

// Campbell Scientific signature algorithm (seed 0xAAAA for the CSAT3B output).
std::uint16_t signature(std::string_view bytes, std::uint16_t seed = 0xAAAA);

// The bytes the signature covers: from the first character of Ux up to and including the
// last character of the diagnostic word. Empty when `line` has fewer than five commas.
std::string_view signed_part(std::string_view line);

// One record as the sensor writes it: 5 decimals for the wind components and Ts ("NaN" for a
// non-finite value), the counter taken mod 64, the signature in lower-case hex, then CR LF.
// (The manual's examples show no terminator bytes; CR LF reads well everywhere and the
// parser accepts CR, LF or CR LF.)
std::string encode_line(const Record& r);

// Parses one line without its terminator (a trailing CR/LF is tolerated): exactly 7 fields,
// numbers or "NaN" for Ux..Ts, a decimal diagnostic word, counter 0..63, 4 hex digits of
// signature (any case) that must match. Empty result otherwise, with the reason in *why.
std::optional<Record> parse_line(std::string_view line, std::string* why = nullptr);

// Incremental parser: feed bytes as they arrive; each complete line with a valid signature
// yields a Record. Lines end at CR or LF (CR LF gives an empty line, which is ignored).
class Parser {
public:
    enum class Event { none, record, signature_error, malformed };
    struct Counters {
        std::uint64_t records = 0, signature_errors = 0, malformed = 0;
        std::uint64_t bytes_discarded = 0;  // bytes of lines that gave no record (terminators excluded)
        std::uint64_t counter_gaps = 0;     // record counter not last + 1 (mod 64): lost records
    };

    Event feed(std::uint8_t byte);
    const Record& record() const { return record_; }
    const Counters& counters() const { return counters_; }

    static constexpr std::size_t max_line = 128;  // real lines are ~40-60 bytes

private:
    Event end_of_line();

    std::string line_;
    bool discarding_ = false;  // an overlong or binary line: skip to the next terminator
    std::optional<int> last_counter_;
    Record record_;
    Counters counters_;
};

}  // namespace manikind::protocol::csat3b
