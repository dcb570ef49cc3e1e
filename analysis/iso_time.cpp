// ISO 8601 UTC timestamps for the interchange format's "utc" column and "t0_utc" key.
// Calendar arithmetic with std::chrono (no time zone database, no locale, no clock).
#include <chrono>
#include <cstdio>

#include "analysis/recording.hpp"

namespace manikind::analysis {

std::string iso_utc_ms(std::int64_t utc_ns) {
    using namespace std::chrono;
    const sys_time<nanoseconds> t{nanoseconds{utc_ns}};
    const auto day = floor<days>(t);
    const year_month_day ymd{day};
    const hh_mm_ss<milliseconds> hms{floor<milliseconds>(t - day)};
    char buf[40];
    std::snprintf(buf, sizeof buf, "%04d-%02u-%02uT%02ld:%02ld:%02lld.%03lldZ", static_cast<int>(ymd.year()),
                  static_cast<unsigned>(ymd.month()), static_cast<unsigned>(ymd.day()),
                  static_cast<long>(hms.hours().count()), static_cast<long>(hms.minutes().count()),
                  static_cast<long long>(hms.seconds().count()), static_cast<long long>(hms.subseconds().count()));
    return buf;
}

std::optional<std::int64_t> parse_iso_utc(std::string_view s) {
    // YYYY-MM-DDTHH:MM:SS[.fff...]Z (the form we write; also what spreadsheets keep)
    auto digits = [&](std::size_t pos, std::size_t n, int& out) {
        if (pos + n > s.size()) return false;
        out = 0;
        for (std::size_t i = pos; i < pos + n; ++i) {
            if (s[i] < '0' || s[i] > '9') return false;
            out = out * 10 + (s[i] - '0');
        }
        return true;
    };
    int y = 0, mo = 0, d = 0, h = 0, mi = 0, sec = 0;
    if (!digits(0, 4, y) || s.size() < 20 || s[4] != '-' || !digits(5, 2, mo) || s[7] != '-' || !digits(8, 2, d) ||
        (s[10] != 'T' && s[10] != ' ') || !digits(11, 2, h) || s[13] != ':' || !digits(14, 2, mi) || s[16] != ':' ||
        !digits(17, 2, sec))
        return std::nullopt;
    std::size_t pos = 19;
    std::int64_t fraction_ns = 0;
    if (pos < s.size() && s[pos] == '.') {
        ++pos;
        std::int64_t scale = 100000000;
        const std::size_t first = pos;
        while (pos < s.size() && s[pos] >= '0' && s[pos] <= '9') {
            fraction_ns += (s[pos] - '0') * scale;
            scale /= 10;
            ++pos;
        }
        if (pos == first) return std::nullopt;
    }
    if (pos + 1 != s.size() || s[pos] != 'Z') return std::nullopt;
    using namespace std::chrono;
    const year_month_day ymd{year{y}, month{static_cast<unsigned>(mo)}, day{static_cast<unsigned>(d)}};
    // int64 nanoseconds since 1970 span 1677-09-21 .. 2262-04-11: keep to whole years inside it
    if (!ymd.ok() || y < 1678 || y > 2261 || h > 23 || mi > 59 || sec > 60) return std::nullopt;
    const auto t = sys_days{ymd} + hours{h} + minutes{mi} + seconds{sec};
    return duration_cast<nanoseconds>(t.time_since_epoch()).count() + fraction_ns;
}

}  // namespace manikind::analysis
