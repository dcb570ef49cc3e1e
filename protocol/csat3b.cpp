#include "protocol/csat3b.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>

namespace manikind::protocol::csat3b {
namespace {

enum class LineStatus { ok, malformed, signature_error };

constexpr std::size_t field_count = 7;

bool is_nan_text(std::string_view f) {
    return f.size() == 3 && (f[0] == 'N' || f[0] == 'n') && (f[1] == 'A' || f[1] == 'a') &&
           (f[2] == 'N' || f[2] == 'n');
}

// A wind component or Ts: a decimal number, or "NaN" when the sensor has no valid data.
std::optional<double> to_value(std::string_view f) {
    if (is_nan_text(f)) return std::numeric_limits<double>::quiet_NaN();
    if (f.empty()) return std::nullopt;
    double v = 0.0;
    const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), v);
    if (ec != std::errc() || ptr != f.data() + f.size() || !std::isfinite(v)) return std::nullopt;
    return v;
}

template <typename T>
std::optional<T> to_unsigned(std::string_view f, int base) {
    if (f.empty()) return std::nullopt;
    T v = 0;
    const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), v, base);
    if (ec != std::errc() || ptr != f.data() + f.size()) return std::nullopt;
    return v;
}

LineStatus fail(std::string* why, const char* reason) {
    if (why) *why = reason;
    return LineStatus::malformed;
}

LineStatus parse(std::string_view line, Record& r, std::string* why) {
    while (!line.empty() && (line.back() == '\r' || line.back() == '\n')) line.remove_suffix(1);
    std::array<std::string_view, field_count> f;
    std::size_t n = 0, start = 0;
    for (std::size_t i = 0; i <= line.size(); ++i)
        if (i == line.size() || line[i] == ',') {
            if (n == field_count) return fail(why, "more than 7 fields");
            f[n++] = line.substr(start, i - start);
            start = i + 1;
        }
    if (n != field_count) return fail(why, "fewer than 7 fields");
    double* const values[] = {&r.ux_m_s, &r.uy_m_s, &r.uz_m_s, &r.sonic_temp_c};
    for (std::size_t i = 0; i < 4; ++i) {
        const auto v = to_value(f[i]);
        if (!v) return fail(why, "Ux, Uy, Uz or Ts is not a number");
        *values[i] = *v;
    }
    const auto diag = to_unsigned<std::uint32_t>(f[4], 10);
    if (!diag) return fail(why, "diagnostic word is not a decimal integer");
    r.diag = *diag;
    const auto counter = to_unsigned<unsigned>(f[5], 10);
    if (!counter || *counter > 63) return fail(why, "record counter is not 0..63");
    r.counter = static_cast<int>(*counter);
    const auto sig = to_unsigned<std::uint16_t>(f[6], 16);
    if (!sig || f[6].size() != 4) return fail(why, "signature is not 4 hex digits");
    r.signature = *sig;
    if (signature(signed_part(line)) != r.signature) {
        if (why) *why = "signature mismatch";
        return LineStatus::signature_error;
    }
    return LineStatus::ok;
}

// "%.5f", or "NaN" as the sensor prints it when it has no valid data.
std::string format_value(double v) {
    if (!std::isfinite(v)) return "NaN";
    char buf[320];  // the longest "%.5f" of a double: sign, 309 digits, point, 5 decimals
    std::snprintf(buf, sizeof buf, "%.5f", v);
    return buf;
}

}  // namespace

std::string diag_text(std::uint32_t diag) {
    if (diag == 0) return "ok";
    static constexpr std::pair<std::uint32_t, const char*> names[] = {
        {low_amplitude, "low_amplitude"}, {high_amplitude, "high_amplitude"},
        {tracking, "tracking"},           {high_delta_c, "high_delta_c"},
        {acquiring, "acquiring"},         {low_voltage, "low_voltage"},
        {trigger_error, "trigger_error"}, {internal_humidity, "internal_humidity"},
        {memory_error, "memory_error"},
    };
    std::string out;
    for (const auto& [bit, name] : names)
        if (diag & bit) {
            if (!out.empty()) out += ',';
            out += name;
        }
    if (const std::uint32_t unknown = diag & ~known_diag_flags) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "unknown_bits_0x%X", static_cast<unsigned>(unknown));
        if (!out.empty()) out += ',';
        out += buf;
    }
    return out;
}

double Record::horizontal_speed_m_s() const { return std::hypot(ux_m_s, uy_m_s); }
double Record::speed_m_s() const { return std::hypot(ux_m_s, uy_m_s, uz_m_s); }

// Campbell Scientific's signature algorithm (the one their dataloggers use for "Signature"),
// seeded with 0xAAAA for the CSAT3B's output.
std::uint16_t signature(std::string_view bytes, std::uint16_t seed) {
    unsigned sig = seed;
    for (const char ch : bytes) {
        const unsigned c = static_cast<unsigned char>(ch);
        const unsigned j = sig;
        sig = (sig << 1) & 0x1FFu;
        if (sig >= 0x100u) ++sig;
        sig = ((sig + (j >> 8) + c) & 0xFFu) | ((j << 8) & 0xFF00u);
    }
    return static_cast<std::uint16_t>(sig);
}

// Manual 8.3.3 says the signature covers the record "up to and including the record
// counter", but every example on p. 55 verifies only over Ux..DiagWord (ending at the last
// digit of the diagnostic word, without the comma after it and without the counter): we
// follow the examples, which is what the sensor sends.
std::string_view signed_part(std::string_view line) {
    std::size_t at = 0;
    for (int commas = 0; commas < 5; ++commas) {
        at = line.find(',', commas == 0 ? 0 : at + 1);
        if (at == std::string_view::npos) return {};
    }
    return line.substr(0, at);
}

std::string encode_line(const Record& r) {
    std::string line = format_value(r.ux_m_s) + ',' + format_value(r.uy_m_s) + ',' +
                       format_value(r.uz_m_s) + ',' + format_value(r.sonic_temp_c) + ',' +
                       std::to_string(r.diag);
    const std::uint16_t sig = signature(line);
    char tail[32];
    std::snprintf(tail, sizeof tail, ",%d,%04x\r\n", ((r.counter % 64) + 64) % 64, static_cast<unsigned>(sig));
    return line + tail;
}

std::optional<Record> parse_line(std::string_view line, std::string* why) {
    Record r;
    if (parse(line, r, why) != LineStatus::ok) return std::nullopt;
    return r;
}

Parser::Event Parser::feed(std::uint8_t byte) {
    if (byte == '\r' || byte == '\n') return end_of_line();
    if (discarding_) {
        ++counters_.bytes_discarded;
        return Event::none;
    }
    if (byte < 0x20 || byte > 0x7e || line_.size() >= max_line) {
        // Binary noise or a line too long to be a record: drop it up to the next terminator.
        counters_.bytes_discarded += line_.size() + 1;
        line_.clear();
        discarding_ = true;
        ++counters_.malformed;
        return Event::malformed;
    }
    line_.push_back(static_cast<char>(byte));
    return Event::none;
}

Parser::Event Parser::end_of_line() {
    if (discarding_) {  // already counted as malformed
        discarding_ = false;
        return Event::none;
    }
    if (line_.empty()) return Event::none;  // the LF of CR LF, or blank lines
    Record r;
    const LineStatus status = parse(line_, r, nullptr);
    if (status != LineStatus::ok) counters_.bytes_discarded += line_.size();
    line_.clear();
    if (status == LineStatus::malformed) {
        ++counters_.malformed;
        return Event::malformed;
    }
    if (status == LineStatus::signature_error) {
        ++counters_.signature_errors;
        return Event::signature_error;
    }
    if (last_counter_ && r.counter != (*last_counter_ + 1) % 64) ++counters_.counter_gaps;
    last_counter_ = r.counter;
    record_ = r;
    ++counters_.records;
    return Event::record;
}

}  // namespace manikind::protocol::csat3b
