// Reader for `manikin-recording/2` and `/1` (docs/formats.md section 1).
//
// Trial CSVs are streamed: read in fixed-size chunks, split into lines in place, each cell
// parsed with std::from_chars straight out of the chunk (no per-line std::string, no
// iostreams). A whole campaign is built in local structures and returned only when every
// file parsed, so an error never leaves a half-imported campaign behind.
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <string_view>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "analysis/input_error.hpp"
#include "analysis/recording.hpp"

namespace manikind::analysis {

namespace {

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// Yields the lines of a file one at a time from a fixed-size buffer. A line longer than the
// buffer grows it (a 99-zone header is still only a few kB).
class ChunkedLineReader {
public:
    ChunkedLineReader(std::FILE* f, const std::string& name, std::size_t chunk_bytes = 1 << 18)
        : file_(f), name_(name), buffer_(chunk_bytes) {}

    // Returns false at end of file. The view stays valid until the next call.
    bool next(std::string_view& line) {
        for (;;) {
            const char* begin = buffer_.data() + pos_;
            const char* end = buffer_.data() + filled_;
            const auto* newline = static_cast<const char*>(std::memchr(begin, '\n', static_cast<std::size_t>(end - begin)));
            if (newline) {
                line = std::string_view(begin, static_cast<std::size_t>(newline - begin));
                pos_ = static_cast<std::size_t>(newline - buffer_.data()) + 1;
                strip_cr(line);
                return true;
            }
            if (eof_) {
                if (begin == end) return false;
                line = std::string_view(begin, static_cast<std::size_t>(end - begin));
                pos_ = filled_;
                strip_cr(line);
                return true;
            }
            // Move the partial line to the front and read the next chunk behind it.
            const std::size_t rest = filled_ - pos_;
            std::memmove(buffer_.data(), buffer_.data() + pos_, rest);
            pos_ = 0;
            filled_ = rest;
            if (filled_ == buffer_.size()) buffer_.resize(buffer_.size() * 2);
            const std::size_t n = std::fread(buffer_.data() + filled_, 1, buffer_.size() - filled_, file_);
            if (n == 0) {
                if (std::ferror(file_))
                    throw InputError(name_, 0, 0, "", fmt::format("cannot read the trial file: {}", std::strerror(errno)));
                eof_ = true;
            }
            filled_ += n;
        }
    }

private:
    static void strip_cr(std::string_view& line) {
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    }
    std::FILE* file_;
    const std::string& name_;
    std::vector<char> buffer_;
    std::size_t pos_ = 0;
    std::size_t filled_ = 0;
    bool eof_ = false;
};

enum class Role { time, air_temp, air_rh, air_speed, wall_temp, skin, flux, utc, channel, quality };

// Physical limits of every numeric column: a value outside is a typing or unit error (°F for
// °C, W for W/m², ms for s), not a measurement, and would poison every mean downstream.
// Chosen wide enough for any climate chamber and manikin test a lab runs; docs/formats.md
// section 1.3 ("Checks on read") lists the same table.
struct ValueRange {
    double min;
    double max;
    const char* unit;
};
constexpr ValueRange kTimeRange_s{0.0, 1e7, "s"};                 // a trial of up to ~115 days
constexpr ValueRange kAirTempRange_c{-60.0, 100.0, "°C"};         // climate chambers span -40..+60 °C
constexpr ValueRange kAirRhRange_pct{-1.0, 101.0, "%"};           // 0..100 plus a sensor's calibration margin
constexpr ValueRange kAirSpeedRange_m_s{0.0, 60.0, "m/s"};        // a wind tunnel's top speed
constexpr ValueRange kWallTempRange_c{-60.0, 150.0, "°C"};        // radiant panels run hotter than air
constexpr ValueRange kSkinTempRange_c{-10.0, 60.0, "°C"};         // held near 33..36 °C; cold starts and faults read lower
constexpr ValueRange kHeatFluxRange_w_m2{-2000.0, 2000.0, "W/m²"};  // beyond solar + full sweating either way
constexpr ValueRange kChannelRange{-1e9, 1e9, ""};  // any unit (campaign.json names it): finite and sane only

struct Column {
    Role role;
    std::size_t zone_index = 0;  // for skin and flux; the recorded channel's index for channel and quality
    std::string name;
    const ValueRange* range = nullptr;  // for numeric columns
    std::string unit;                   // for messages
};

const ValueRange* range_of(Role role) {
    switch (role) {
        case Role::time: return &kTimeRange_s;
        case Role::air_temp: return &kAirTempRange_c;
        case Role::air_rh: return &kAirRhRange_pct;
        case Role::air_speed: return &kAirSpeedRange_m_s;
        case Role::wall_temp: return &kWallTempRange_c;
        case Role::skin: return &kSkinTempRange_c;
        case Role::flux: return &kHeatFluxRange_w_m2;
        case Role::channel: return &kChannelRange;
        case Role::utc:
        case Role::quality: return nullptr;
    }
    return nullptr;
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
    return s;
}

// "z07_skin_c" -> 7 and "skin"; returns 0 when the name is not a zone column.
int zone_column_number(std::string_view name, std::string_view& kind) {
    if (name.size() < 4 || name[0] != 'z' || name[1] < '0' || name[1] > '9' || name[2] < '0' || name[2] > '9' ||
        name[3] != '_')
        return 0;
    kind = name.substr(4);
    return (name[1] - '0') * 10 + (name[2] - '0');
}

std::vector<Column> parse_header(std::string_view line, const ZoneMap& map, const std::string& file,
                                 const std::vector<RecordedChannel>& channels) {
    std::map<std::string, std::size_t> channel_index;
    for (std::size_t k = 0; k < channels.size(); ++k) channel_index[channels[k].column()] = k;
    std::vector<Column> columns;
    auto add = [&](Role role, std::size_t index, const std::string& name) {
        const ValueRange* range = range_of(role);
        const std::string unit = role == Role::channel ? channels[index].unit : range ? range->unit : "";
        columns.push_back({role, index, name, range, unit});
    };
    std::set<std::string> seen;
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = line.find(',', start);
        const std::string_view raw = line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start);
        const std::string name(trim(raw));
        const std::size_t column = start + 1;
        if (name.empty()) throw InputError(file, 1, column, "", "empty column name in the header");
        if (!seen.insert(name).second) throw InputError(file, 1, column, name, "column appears twice in the header");
        std::string_view kind;
        const int zone = zone_column_number(name, kind);
        if (name == "t_s") add(Role::time, 0, name);
        else if (name == "air_temp_c") add(Role::air_temp, 0, name);
        else if (name == "air_rh_pct") add(Role::air_rh, 0, name);
        else if (name == "air_speed_m_s") add(Role::air_speed, 0, name);
        else if (name == "wall_temp_c") add(Role::wall_temp, 0, name);
        else if (name == "utc") add(Role::utc, 0, name);
        else if (const auto it = channel_index.find(name); it != channel_index.end())
            add(Role::channel, it->second, name);
        else if (name.size() > 2 && name.ends_with(".q") && channel_index.count(name.substr(0, name.size() - 2)))
            add(Role::quality, channel_index.at(name.substr(0, name.size() - 2)), name);
        else if (zone > 0 && (kind == "skin_c" || kind == "flux_w_m2")) {
            if (static_cast<std::size_t>(zone) > map.size())
                throw InputError(file, 1, column, name,
                                 fmt::format("unknown zone column: the zone map '{}' has zones 01..{:02}", map.name, map.size()));
            add(kind == "skin_c" ? Role::skin : Role::flux, static_cast<std::size_t>(zone - 1), name);
        } else {
            throw InputError(file, 1, column, name,
                             "unknown column; expected t_s, utc, air_temp_c, air_rh_pct, air_speed_m_s, wall_temp_c, "
                             "zNN_skin_c, zNN_flux_w_m2 or a channel campaign.json lists under \"channels\" "
                             "(<device>.<channel> and <device>.<channel>.q)");
        }
        if (comma == std::string_view::npos) break;
        start = comma + 1;
    }
    auto require = [&](const std::string& name) {
        if (!seen.count(name)) throw InputError(file, 1, 0, name, "required column is missing from the header");
    };
    require("t_s");
    require("air_temp_c");
    require("air_rh_pct");
    for (const auto& z : map.zones) {
        require(fmt::format("z{:02}_skin_c", z.zone));
        require(fmt::format("z{:02}_flux_w_m2", z.zone));
    }
    return columns;
}

// Parses one cell: empty -> NaN (a sensor slower than the manikin), "nan" -> NaN, else a
// finite number. Returns false on anything else.
bool parse_cell(std::string_view cell, double& value) {
    cell = trim(cell);
    if (cell.empty()) {
        value = kNaN;
        return true;
    }
    const char* first = cell.data();
    const char* last = cell.data() + cell.size();
    if (*first == '+') ++first;  // from_chars refuses a leading '+', spreadsheets write one
    const auto [ptr, ec] = std::from_chars(first, last, value);
    if (ec != std::errc() || ptr != last) return false;
    if (std::isinf(value)) return false;
    if (std::isnan(value)) value = kNaN;  // normalise the sign/payload of a written "nan"
    return true;
}

// Far above a week at 1 Hz with 99 zones (~0.7 GB); a larger "trial" is the wrong file.
constexpr std::uintmax_t kMaxTrialFileBytes = std::uintmax_t{1} << 30;
// campaign.json is metadata, a few kB; read whole, so bounded well below the trials.
constexpr std::uintmax_t kMaxCampaignJsonBytes = std::uintmax_t{16} << 20;

// Why `path` cannot be read as `what` ("the trial file"), or "" (also when it does not
// exist: opening says so). A FIFO would block and a device like /dev/zero never ends, so
// only regular files of at most `max_bytes` pass.
std::string file_problem(const std::filesystem::path& path, const char* what, std::uintmax_t max_bytes) {
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (!std::filesystem::exists(status)) return "";
    if (std::filesystem::is_directory(status)) return fmt::format("{} is a directory, not a regular file", what);
    if (!std::filesystem::is_regular_file(status))
        return fmt::format("{} is not a regular file (a device, FIFO or socket)", what);
    const auto bytes = std::filesystem::file_size(path, ec);
    if (!ec && bytes > max_bytes)
        return fmt::format("{} holds {} bytes, more than the {} MiB it may hold", what, bytes, max_bytes >> 20);
    return "";
}

std::string shorten(std::string_view s) {
    if (s.size() <= 40) return std::string(s);
    return std::string(s.substr(0, 37)) + "...";
}

}  // namespace

std::vector<std::string> trial_csv_columns(const ZoneMap& map, bool with_air_speed, bool with_wall_temp) {
    std::vector<std::string> names{"t_s", "air_temp_c", "air_rh_pct"};
    if (with_air_speed) names.emplace_back("air_speed_m_s");
    if (with_wall_temp) names.emplace_back("wall_temp_c");
    for (const auto& z : map.zones) names.push_back(fmt::format("z{:02}_skin_c", z.zone));
    for (const auto& z : map.zones) names.push_back(fmt::format("z{:02}_flux_w_m2", z.zone));
    return names;
}

// A quality cell: empty (no sample in the interval) or a code 0..254.
bool parse_quality(std::string_view cell, std::uint8_t& code) {
    cell = trim(cell);
    if (cell.empty()) {
        code = kNoSample;
        return true;
    }
    unsigned v = 0;
    const auto [ptr, ec] = std::from_chars(cell.data(), cell.data() + cell.size(), v);
    if (ec != std::errc() || ptr != cell.data() + cell.size() || v >= kNoSample) return false;
    code = static_cast<std::uint8_t>(v);
    return true;
}

TrialData read_trial_csv(const std::filesystem::path& path, const ZoneMap& map, const std::string& file,
                         const std::vector<RecordedChannel>& channels) {
    // Checked before opening: a FIFO or a device would block or never end (/dev/zero).
    if (const std::string problem = file_problem(path, "the trial file", kMaxTrialFileBytes); !problem.empty())
        throw InputError(file, 0, 0, "", problem);
    FilePtr f(std::fopen(path.c_str(), "rb"));
    if (!f) throw InputError(file, 0, 0, "", fmt::format("cannot open the trial file: {}", std::strerror(errno)));
    ChunkedLineReader reader(f.get(), file);
    std::string_view line;
    std::size_t line_no = 0;
    bool have_header = false;
    while (!have_header) {
        if (!reader.next(line)) throw InputError(file, line_no + 1, 1, "", "empty file: expected a header row");
        ++line_no;
        have_header = !trim(line).empty();
    }
    // A UTF-8 byte-order mark from a spreadsheet export is not part of the first name.
    if (line.size() >= 3 && line.substr(0, 3) == "\xEF\xBB\xBF") line.remove_prefix(3);
    const std::vector<Column> columns = parse_header(line, map, file, channels);

    TrialData data;
    data.skin_temp_c.resize(map.size());
    data.heat_flux_w_m2.resize(map.size());
    data.channel_values.resize(channels.size());
    data.channel_quality.resize(channels.size());
    std::vector<bool> has_values(channels.size()), has_quality(channels.size());
    // Where each column's values go, resolved once.
    std::vector<std::vector<double>*> target(columns.size());
    for (std::size_t c = 0; c < columns.size(); ++c) {
        switch (columns[c].role) {
            case Role::time: target[c] = &data.t_s; break;
            case Role::air_temp: target[c] = &data.air_temp_c; break;
            case Role::air_rh: target[c] = &data.air_rh_pct; break;
            case Role::air_speed: target[c] = &data.air_speed_m_s; break;
            case Role::wall_temp: target[c] = &data.wall_temp_c; break;
            case Role::skin: target[c] = &data.skin_temp_c[columns[c].zone_index]; break;
            case Role::flux: target[c] = &data.heat_flux_w_m2[columns[c].zone_index]; break;
            case Role::channel:
                target[c] = &data.channel_values[columns[c].zone_index];
                has_values[columns[c].zone_index] = true;
                break;
            case Role::utc:
            case Role::quality:
                target[c] = nullptr;  // not numbers: parsed below by role
                if (columns[c].role == Role::quality) has_quality[columns[c].zone_index] = true;
                break;
        }
    }
    std::size_t time_column = 0;
    for (std::size_t c = 0; c < columns.size(); ++c)
        if (columns[c].role == Role::time) time_column = c;

    double previous_t_s = -std::numeric_limits<double>::infinity();
    // Checks a parsed number against its column's physical range and the time order, then stores it.
    auto store_number = [&](std::size_t c, double value, std::string_view cell, std::size_t start) {
        const std::size_t at_line = line_no;
        if (const ValueRange& r = *columns[c].range; !std::isnan(value) && (value < r.min || value > r.max))
            throw InputError(file, at_line, start + 1, columns[c].name,
                             fmt::format("{} {} is outside the physical range {:g}..{:g} {}", shorten(trim(cell)),
                                         columns[c].unit, r.min, r.max, columns[c].unit));
        if (c == time_column) {
            if (std::isnan(value)) throw InputError(file, at_line, start + 1, "t_s", "the time cell is empty");
            if (value <= previous_t_s)
                throw InputError(file, at_line, start + 1, "t_s",
                                 fmt::format("time goes backwards or repeats: {} s after {} s on an earlier row; "
                                             "rows must be in increasing time order", value, previous_t_s));
            previous_t_s = value;
        }
        target[c]->push_back(value);
    };
    // Room for the rows the file holds, judged from its size and the first data row, so the
    // columns are not copied as they grow.
    bool reserved = false;
    std::error_code size_error;
    const auto file_bytes = std::filesystem::file_size(path, size_error);
    while (reader.next(line)) {
        ++line_no;
        if (trim(line).empty()) continue;  // a blank line carries no sample
        if (!reserved && !size_error && !line.empty()) {
            reserved = true;
            // A row holds at least a comma per column, which bounds the guess if this row is sparse.
            const std::size_t rows = std::min(static_cast<std::size_t>(file_bytes / (line.size() + 1)) * 9 / 8 + 16,
                                              static_cast<std::size_t>(file_bytes / columns.size()) + 1);
            for (auto* t : target)
                if (t) t->reserve(rows);
        }
        const char* const line_end = line.data() + line.size();
        std::size_t start = 0;
        std::size_t c = 0;
        for (;; ++c) {
            // The common cell, a plain number followed by ',' or the end of the line, is parsed
            // in place as the parse floor does; anything else (blank, spaces, '+', inf, a
            // malformed number, a field past the header's) goes the careful way below.
            if (c < columns.size() && target[c]) {
                double value = 0.0;
                const auto [ptr, ec] = std::from_chars(line.data() + start, line_end, value);
                if (ec == std::errc() && (ptr == line_end || *ptr == ',') && ptr != line.data() + start &&
                    !std::isinf(value)) {
                    if (std::isnan(value)) value = kNaN;  // normalise the sign/payload of a written "nan"
                    const auto end = static_cast<std::size_t>(ptr - line.data());
                    store_number(c, value, line.substr(start, end - start), start);
                    if (ptr == line_end) break;
                    start = end + 1;
                    continue;
                }
            }
            const std::size_t comma = line.find(',', start);
            if (c >= columns.size())
                throw InputError(file, line_no, start + 1, "",
                                 fmt::format("too many fields: the header has {} columns", columns.size()));
            const std::string_view cell =
                line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start);
            if (!target[c]) {
                if (columns[c].role == Role::utc) {
                    const auto utc = parse_iso_utc(trim(cell));
                    if (!utc)
                        throw InputError(file, line_no, start + 1, "utc",
                                         fmt::format("expected an ISO 8601 UTC time like 2026-11-24T01:35:07.250Z, found '{}'",
                                                     shorten(cell)));
                    data.utc_ns.push_back(*utc);
                } else {
                    std::uint8_t code = 0;
                    if (!parse_quality(cell, code))
                        throw InputError(file, line_no, start + 1, columns[c].name,
                                         fmt::format("expected a quality code (0 good, 1 stale, 2 out of range, 3 "
                                                     "communication error) or an empty cell, found '{}'", shorten(cell)));
                    data.channel_quality[columns[c].zone_index].push_back(code);
                }
                if (comma == std::string_view::npos) break;
                start = comma + 1;
                continue;
            }
            double value = 0.0;
            if (!parse_cell(cell, value))
                throw InputError(file, line_no, start + 1, columns[c].name,
                                 fmt::format("expected a number, found '{}'", shorten(cell)));
            store_number(c, value, cell, start);
            if (comma == std::string_view::npos) break;
            start = comma + 1;
        }
        if (c + 1 != columns.size())
            throw InputError(file, line_no, line.size() + 1, "",
                             fmt::format("too few fields: found {}, the header has {} columns", c + 1, columns.size()));
    }
    // A declared channel whose column or quality column is absent reads as "no sample".
    for (std::size_t k = 0; k < channels.size(); ++k) {
        if (!has_values[k]) data.channel_values[k].assign(data.t_s.size(), kNaN);
        if (!has_quality[k])
            data.channel_quality[k].assign(data.t_s.size(), has_values[k] ? std::uint8_t{0} : kNoSample);
    }
    return data;
}

// --- campaign.json ------------------------------------------------------------------------

namespace {

using nlohmann::json;

struct Located {
    std::size_t line = 0;
    std::size_t column = 0;
};

Located locate_offset(const std::string& text, std::size_t offset) {
    Located at{1, 1};
    for (std::size_t i = 0; i < offset && i < text.size(); ++i) {
        if (text[i] == '\n') {
            ++at.line;
            at.column = 1;
        } else {
            ++at.column;
        }
    }
    return at;
}

// Position of the nth (0-based) occurrence of `needle`; {0,0} when absent. Used to point at
// a trial entry by its quoted id: nlohmann's DOM does not keep positions.
Located locate(const std::string& text, const std::string& needle, std::size_t nth = 0) {
    std::size_t pos = 0;
    for (std::size_t i = 0;; ++i) {
        pos = text.find(needle, pos);
        if (pos == std::string::npos) return {};
        if (i == nth) return locate_offset(text, pos);
        pos += needle.size();
    }
}

// The key whose value starts at `pos` ("flux" in `"flux": 1e400`), or "" inside an array.
std::string key_before(const std::string& text, std::size_t pos) {
    auto skip_space = [&](std::size_t p) {
        while (p > 0 && std::isspace(static_cast<unsigned char>(text[p - 1]))) --p;
        return p;
    };
    std::size_t p = skip_space(pos);
    if (p == 0 || text[p - 1] != ':') return "";
    p = skip_space(p - 1);
    if (p < 2 || text[p - 1] != '"') return "";
    const std::size_t open = text.rfind('"', p - 2);
    return open == std::string::npos ? "" : text.substr(open + 1, p - 2 - open);
}

class CampaignJson {
public:
    CampaignJson(std::string file, std::string text) : file_(std::move(file)), text_(std::move(text)) {}

    [[noreturn]] void fail(const std::string& field, const std::string& message, Located at = {}) const {
        throw InputError(file_, at.line, at.column, field, message);
    }

    double number(const json& obj, const std::string& key, const std::string& path, Located at) const {
        const auto& v = obj.at(key);
        if (!v.is_number()) fail(path + key, fmt::format("expected a number, found {}", v.dump()), at);
        const double x = v.get<double>();
        if (!std::isfinite(x)) fail(path + key, "expected a finite number", at);
        return x;
    }
    std::string string(const json& obj, const std::string& key, const std::string& path, Located at) const {
        const auto& v = obj.at(key);
        if (!v.is_string()) fail(path + key, fmt::format("expected a string, found {}", v.dump()), at);
        return v.get<std::string>();
    }
    // An integer within min..max (an int either way: get<int> would wrap silently).
    int integer(const json& obj, const std::string& key, const std::string& path, Located at,
                int min = std::numeric_limits<int>::min(), int max = std::numeric_limits<int>::max()) const {
        const auto& v = obj.at(key);
        if (!v.is_number_integer()) fail(path + key, fmt::format("expected an integer, found {}", v.dump()), at);
        // Non-negative integers are unsigned in nlohmann; those beyond int64 are not int64s.
        const bool in_range = v.is_number_unsigned()
                                  ? v.get<std::uint64_t>() <= static_cast<std::uint64_t>(max) &&
                                        static_cast<std::int64_t>(v.get<std::uint64_t>()) >= min
                                  : v.get<std::int64_t>() >= min && v.get<std::int64_t>() <= max;
        if (!in_range) fail(path + key, fmt::format("must be within {}..{}, found {}", min, max, v.dump()), at);
        return static_cast<int>(v.get<std::int64_t>());
    }

    const std::string& file() const { return file_; }
    const std::string& text() const { return text_; }

private:
    std::string file_;
    std::string text_;
};

ZoneMap parse_inline_zone_map(const json& arr, const CampaignJson& cj) {
    ZoneMap map;
    map.name = "inline";
    const Located at = locate(cj.text(), "\"zone_map\"");
    for (std::size_t i = 0; i < arr.size(); ++i) {
        const auto& e = arr[i];
        const std::string path = fmt::format("zone_map[{}].", i);
        if (!e.is_object()) cj.fail(path, "expected an object", at);
        for (const char* key : {"zone", "name", "region", "area_m2"})
            if (!e.contains(key)) cj.fail(path + key, "required key is missing", at);
        Zone z;
        z.zone = cj.integer(e, "zone", path, at);
        z.name = cj.string(e, "name", path, at);
        z.region = cj.string(e, "region", path, at);
        z.segment = e.contains("segment") ? cj.string(e, "segment", path, at) : z.region;
        z.side = e.contains("side") ? cj.string(e, "side", path, at) : "c";
        z.area_m2 = cj.number(e, "area_m2", path, at);
        z.centroid_height_m = e.contains("centroid_height_m") ? cj.number(e, "centroid_height_m", path, at) : 0.0;
        if (e.contains("facing")) {
            z.facing = cj.string(e, "facing", path, at);
            if (!valid_facing(z.facing)) cj.fail(path + "facing", "expected front, back, up, down or none", at);
        }
        map.zones.push_back(std::move(z));
    }
    std::sort(map.zones.begin(), map.zones.end(), [](const Zone& a, const Zone& b) { return a.zone < b.zone; });
    if (auto problem = validate_zone_map(map); !problem.empty()) cj.fail("zone_map", problem, at);
    return map;
}

InstrumentSpec parse_instrument(const json& v, const std::string& channel, const CampaignJson& cj,
                                std::vector<std::string>& warnings) {
    const std::string path = "instruments." + channel + ".";
    const Located at = locate(cj.text(), "\"" + channel + "\"");
    if (!v.is_object()) cj.fail("instruments." + channel, "expected an object {\"accuracy\": ...}", at);
    if (!v.contains("accuracy")) cj.fail(path + "accuracy", "required key is missing", at);
    InstrumentSpec spec;
    spec.accuracy = cj.number(v, "accuracy", path, at);
    if (v.contains("accuracy_of_reading")) spec.accuracy_of_reading = cj.number(v, "accuracy_of_reading", path, at);
    if (spec.accuracy < 0.0 || spec.accuracy_of_reading < 0.0) cj.fail(path + "accuracy", "must not be negative", at);
    if (v.contains("distribution")) {
        const std::string d = cj.string(v, "distribution", path, at);
        const auto parsed = distribution_from_string(d);
        if (!parsed)
            cj.fail(path + "distribution",
                    fmt::format("unknown distribution '{}'; expected rectangular, normal (stated at k = 2) or triangular", d), at);
        spec.distribution = *parsed;
    }
    for (const auto& [key, value] : v.items()) {
        (void)value;
        if (key != "accuracy" && key != "accuracy_of_reading" && key != "distribution")
            warnings.push_back(fmt::format("{}:{}:{}: unknown key '{}{}' ignored", cj.file(), at.line, at.column, path, key));
    }
    return spec;
}

std::vector<RecordedChannel> parse_channels(const json& arr, const CampaignJson& cj) {
    const Located at = locate(cj.text(), "\"channels\"");
    if (!arr.is_array()) cj.fail("channels", "expected an array of {\"device\", \"channel\", \"unit\"}", at);
    std::vector<RecordedChannel> out;
    std::set<std::string> seen;
    for (std::size_t i = 0; i < arr.size(); ++i) {
        const std::string path = fmt::format("channels[{}].", i);
        const auto& e = arr[i];
        if (!e.is_object()) cj.fail(fmt::format("channels[{}]", i), "expected an object", at);
        for (const char* key : {"device", "channel", "unit"})
            if (!e.contains(key)) cj.fail(path + key, "required key is missing", at);
        RecordedChannel ch{cj.string(e, "device", path, at), cj.string(e, "channel", path, at), cj.string(e, "unit", path, at)};
        if (ch.device.empty() || ch.name.empty() || ch.device.find_first_of(",\"\n") != std::string::npos ||
            ch.name.find_first_of(",\"\n") != std::string::npos)
            cj.fail(path + "channel", "device and channel must be non-empty and contain no comma, quote or newline", at);
        if (e.contains("column") && cj.string(e, "column", path, at) != ch.column())
            cj.fail(path + "column", fmt::format("expected \"{}\" (device.channel)", ch.column()), at);
        if (!seen.insert(ch.column()).second) cj.fail(path + "channel", fmt::format("'{}' is listed twice", ch.column()), at);
        out.push_back(std::move(ch));
    }
    return out;
}

// The trial file must lie inside the campaign folder (after resolving symlinks) and be a
// regular file: a campaign from elsewhere must not make us read /etc/passwd or /dev/zero.
void check_trial_file(const std::filesystem::path& folder, const std::string& file, const std::string& field,
                      const CampaignJson& cj, Located at) {
    const std::filesystem::path relative(file);
    if (relative.empty() || relative.has_root_name() || relative.has_root_directory())
        cj.fail(field, fmt::format("'{}' must be a path relative to the campaign folder", file), at);
    const auto normal = relative.lexically_normal();
    if (!normal.empty() && *normal.begin() == "..")
        cj.fail(field, fmt::format("'{}' leads out of the campaign folder", file), at);
    std::error_code ec;
    const auto root = std::filesystem::canonical(folder, ec);
    if (ec) cj.fail(field, fmt::format("cannot resolve the campaign folder: {}", ec.message()), at);
    const auto resolved = std::filesystem::weakly_canonical(root / normal, ec);
    if (ec) cj.fail(field, fmt::format("cannot resolve '{}': {}", file, ec.message()), at);
    const auto inside = resolved.lexically_relative(root);
    if (inside.empty() || *inside.begin() == "..")
        cj.fail(field, fmt::format("'{}' is a link that leads out of the campaign folder", file), at);
    if (const std::string problem = file_problem(resolved, "the trial file", kMaxTrialFileBytes); !problem.empty())
        cj.fail(field, fmt::format("'{}': {}", file, problem), at);
}

TrialInfo parse_trial_info(const json& t, std::size_t index, const CampaignJson& cj, const std::filesystem::path& folder,
                           const ZoneMap& map, std::vector<std::string>& warnings) {
    const std::string path = fmt::format("trials[{}].", index);
    if (!t.is_object()) cj.fail(fmt::format("trials[{}]", index), "expected an object");
    if (!t.contains("id")) cj.fail(path + "id", "required key is missing");
    TrialInfo info;
    info.id = cj.string(t, "id", path, {});
    const Located at = locate(cj.text(), "\"" + info.id + "\"");
    // A key of this trial: searched from the '{' that opens the trial's object (first one
    // with this id; a duplicate id is refused later anyway).
    const std::size_t id_pos = cj.text().find("\"" + info.id + "\"");
    const std::size_t object_pos = id_pos == std::string::npos ? 0 : cj.text().rfind('{', id_pos);
    auto at_key = [&](const std::string& key) {
        const std::size_t p = cj.text().find("\"" + key + "\"", object_pos == std::string::npos ? 0 : object_pos);
        return p == std::string::npos ? at : locate_offset(cj.text(), p);
    };
    if (info.id.empty() || info.id.find_first_of("/\\") != std::string::npos)
        cj.fail(path + "id", "a trial id must be non-empty and contain no slash", at);
    if (!t.contains("case")) cj.fail(path + "case", "required key is missing", at);
    info.case_id = cj.integer(t, "case", path, at_key("case"), 0);
    info.replicate = t.contains("replicate") ? cj.integer(t, "replicate", path, at_key("replicate"), 1) : 0;  // 0: numbered below
    info.file = t.contains("file") ? cj.string(t, "file", path, at_key("file")) : "trials/" + info.id + ".csv";
    check_trial_file(folder, info.file, path + "file", cj, at_key("file"));
    if (t.contains("skin_setpoint_c")) info.skin_setpoint_c = cj.number(t, "skin_setpoint_c", path, at_key("skin_setpoint_c"));
    if (t.contains("wet")) {
        if (!t.at("wet").is_boolean()) cj.fail(path + "wet", "expected true or false", at);
        info.wettedness = t.at("wet").get<bool>() ? 1.0 : 0.0;
    }
    if (t.contains("wettedness")) {
        const double w = cj.number(t, "wettedness", path, at_key("wettedness"));
        if (w < 0.0 || w > 1.0) cj.fail(path + "wettedness", fmt::format("must be within 0..1, found {}", w), at_key("wettedness"));
        info.wettedness = w;
    }
    if (t.contains("chamber_setpoint")) {
        const auto& cs = t.at("chamber_setpoint");
        if (!cs.is_object()) cj.fail(path + "chamber_setpoint", "expected an object", at);
        if (cs.contains("temp_c")) info.chamber_setpoint_temp_c = cj.number(cs, "temp_c", path + "chamber_setpoint.", at);
        if (cs.contains("rh_pct")) info.chamber_setpoint_rh_pct = cj.number(cs, "rh_pct", path + "chamber_setpoint.", at);
    }
    if (t.contains("started_utc")) info.started_utc = cj.string(t, "started_utc", path, at_key("started_utc"));
    if (t.contains("t0_utc")) {
        info.t0_utc_ns = parse_iso_utc(cj.string(t, "t0_utc", path, at_key("t0_utc")));
        if (!info.t0_utc_ns) cj.fail(path + "t0_utc", "expected an ISO 8601 UTC time like 2026-11-24T01:35:07.250Z", at);
    }
    if (t.contains("ensemble")) {
        info.ensemble = cj.string(t, "ensemble", path, at_key("ensemble"));
        if (info.ensemble.empty()) cj.fail(path + "ensemble", "expected an ensemble id (or \"nude\")", at_key("ensemble"));
    }
    if (t.contains("test")) {
        info.test = cj.string(t, "test", path, at_key("test"));
        if (info.test != "insulation" && info.test != "evaporative")
            cj.fail(path + "test", fmt::format("expected \"insulation\" or \"evaporative\", found '{}'", info.test), at_key("test"));
    }
    if (t.contains("control")) {
        info.control = cj.string(t, "control", path, at_key("control"));
        // The daemon's modes (docs/daemon.md): an export of a comfort or constant-heat-flux campaign
        // carries them, and teq reads it back.
        if (info.control != "physiological" && info.control != "constant-skin" && info.control != "comfort" &&
            info.control != "constant-heat-flux")
            cj.fail(path + "control",
                    fmt::format("expected \"constant-skin\", \"constant-heat-flux\", \"comfort\" or \"physiological\", found '{}'",
                                info.control),
                    at_key("control"));
        if (info.control == "constant-skin") info.control.clear();
    }
    if (t.contains("local")) {
        // The room the campaign stated for the trial's case, per zone (docs/formats.md).
        std::string why;
        info.local = parse_local_room(map, t.at("local"), why);
        if (!why.empty()) {
            const auto colon = why.find(": ");
            cj.fail(path + "local" + (colon == std::string::npos ? "" : why.substr(0, colon)),
                    colon == std::string::npos ? why : why.substr(colon + 2), at_key("local"));
        }
    }
    if (t.contains("partial")) {
        if (!t.at("partial").is_boolean()) cj.fail(path + "partial", fmt::format("expected true or false, found {}", t.at("partial").dump()), at_key("partial"));
        info.partial = t.at("partial").get<bool>();
        // Said, not hidden: its steady-state verdict and flux are of the trial so far.
        if (info.partial)
            warnings.push_back(fmt::format("{}:{}:{}: trial '{}' was exported while running (\"partial\": true): its data end at "
                                           "the last reading committed then, and any verdict on it is of the trial so far",
                                           cj.file(), at.line, at.column, info.id));
    }
    static const std::set<std::string> known{"id",        "case",        "replicate", "file",     "skin_setpoint_c",
                                             "wet",       "wettedness",  "chamber_setpoint",      "started_utc",
                                             "t0_utc",    "ensemble",    "test",      "control",  "partial", "local"};
    for (const auto& [key, value] : t.items()) {
        (void)value;
        if (!known.count(key))
            warnings.push_back(fmt::format("{}:{}:{}: unknown key '{}{}' ignored", cj.file(), at.line, at.column, path, key));
    }
    return info;
}

// campaign.json, every check included (trial files are checked to exist, not parsed).
Campaign read_metadata_checked(const std::filesystem::path& folder, const ReadOptions& options) {
    const std::filesystem::path json_path = folder / "campaign.json";
    const std::string json_file = json_path.string();
    if (const std::string problem = file_problem(json_path, "campaign.json", kMaxCampaignJsonBytes); !problem.empty())
        throw InputError(json_file, 0, 0, "", problem);
    std::ifstream in(json_path, std::ios::binary);
    if (!in) {
        std::error_code ec;
        if (!std::filesystem::exists(folder, ec))
            throw InputError(folder.string(), 0, 0, "", "no such campaign folder");
        throw InputError(json_file, 0, 0, "", "cannot open campaign.json (a campaign is a folder with campaign.json and trials/)");
    }
    std::stringstream ss;
    ss << in.rdbuf();  // campaign.json is metadata (a few kB); the samples are streamed below
    const CampaignJson cj(json_file, ss.str());

    json doc;
    try {
        doc = json::parse(cj.text());
    } catch (const json::parse_error& e) {
        const Located at = locate_offset(cj.text(), e.byte > 0 ? e.byte - 1 : 0);
        std::string what = e.what();
        if (const auto colon = what.rfind(": "); colon != std::string::npos) what = what.substr(colon + 2);
        cj.fail("", "invalid JSON: " + what, at);
    } catch (const json::out_of_range& e) {
        // A number beyond double ("1e400"): nlohmann names the token, not where it is.
        const std::string what = e.what();
        const auto open = what.find('\'');
        const std::string token =
            open == std::string::npos ? "" : what.substr(open + 1, what.rfind('\'') - open - 1);
        const std::size_t pos = token.empty() ? std::string::npos : cj.text().find(token);
        cj.fail(pos == std::string::npos ? "" : key_before(cj.text(), pos),
                fmt::format("number {} is out of range (beyond ±1.8e308)", token),
                pos == std::string::npos ? Located{} : locate_offset(cj.text(), pos));
    }
    if (!doc.is_object()) cj.fail("", "expected a JSON object at the top level", {1, 1});

    Campaign campaign;
    if (!doc.contains("format")) cj.fail("format", fmt::format("required key is missing (expected \"{}\")", kRecordingFormat));
    const std::string format = cj.string(doc, "format", "", locate(cj.text(), "\"format\""));
    if (format != kRecordingFormat && format != kRecordingFormatV1)
        cj.fail("format",
                fmt::format("unsupported format '{}'; this program reads '{}' and '{}'", format, kRecordingFormat,
                            kRecordingFormatV1),
                locate(cj.text(), "\"format\""));
    campaign.name = doc.contains("name") ? cj.string(doc, "name", "", locate(cj.text(), "\"name\""))
                                         : folder.filename().string();

    campaign.zone_map = andi35_zone_map();
    if (doc.contains("zone_map")) {
        const auto& zm = doc.at("zone_map");
        if (zm.is_string()) {
            if (zm.get<std::string>() != "andi35")
                cj.fail("zone_map", fmt::format("unknown built-in zone map '{}'; built in: andi35 (or give an inline array)",
                                                zm.get<std::string>()),
                        locate(cj.text(), "\"zone_map\""));
        } else if (zm.is_array()) {
            campaign.zone_map = parse_inline_zone_map(zm, cj);
            campaign.zone_map_inline = true;
        } else {
            cj.fail("zone_map", "expected a built-in map name or an array of zones", locate(cj.text(), "\"zone_map\""));
        }
    }

    campaign.instruments = options.default_instruments;
    if (doc.contains("instruments")) {
        const auto& inst = doc.at("instruments");
        if (!inst.is_object()) cj.fail("instruments", "expected an object keyed by channel", locate(cj.text(), "\"instruments\""));
        for (const auto& [channel, spec] : inst.items()) {
            const bool known = std::any_of(std::begin(kInstrumentChannels), std::end(kInstrumentChannels),
                                           [&channel_name = channel](const char* c) { return channel_name == c; });  // clang 14: no binding captures
            if (!known) {
                const Located at = locate(cj.text(), "\"" + channel + "\"");
                campaign.warnings.push_back(fmt::format("{}:{}:{}: unknown instrument channel 'instruments.{}' ignored",
                                                        json_file, at.line, at.column, channel));
                continue;
            }
            campaign.instruments[channel] = parse_instrument(spec, channel, cj, campaign.warnings);
        }
    }

    if (doc.contains("channels")) campaign.channels = parse_channels(doc.at("channels"), cj);
    if (doc.contains("provenance")) {
        const auto& p = doc.at("provenance");
        if (!p.is_object()) cj.fail("provenance", "expected an object", locate(cj.text(), "\"provenance\""));
        for (const auto& [key, value] : p.items())
            campaign.provenance[key] = value.is_string() ? value.get<std::string>() : value.dump();
    }
    if (doc.contains("heat_flux_sign") && doc.at("heat_flux_sign") != kHeatFluxSign)
        cj.fail("heat_flux_sign",
                fmt::format("this program reads heat flux as '{}', the file says {}", kHeatFluxSign,
                            doc.at("heat_flux_sign").dump()),
                locate(cj.text(), "\"heat_flux_sign\""));

    if (doc.contains("ensembles")) {
        const auto& ens = doc.at("ensembles");
        const Located at = locate(cj.text(), "\"ensembles\"");
        if (!ens.is_object()) cj.fail("ensembles", "expected an object keyed by ensemble id", at);
        for (const auto& [id, e] : ens.items()) {
            const std::string path = "ensembles." + id + ".";
            if (id.empty() || id == "nude")
                cj.fail("ensembles." + id, "an ensemble id must be non-empty and not \"nude\" (the bare manikin needs no entry)", at);
            if (!e.is_object()) cj.fail("ensembles." + id, "expected an object with description and optionally fcl", at);
            Ensemble ensemble;
            if (e.contains("description")) ensemble.description = cj.string(e, "description", path, at);
            if (e.contains("fcl")) {
                const double fcl = cj.number(e, "fcl", path, at);
                // ISO 9920's clothing area factors run from 1.0 (nude) to about 1.7 (arctic).
                if (!(fcl >= 1.0 && fcl <= 3.0)) cj.fail(path + "fcl", fmt::format("must be within 1..3, found {}", fcl), at);
                ensemble.fcl = fcl;
            }
            if (e.contains("fcl_u")) {
                const double u = cj.number(e, "fcl_u", path, at);
                if (!(u >= 0.0 && u <= 1.0)) cj.fail(path + "fcl_u", fmt::format("must be within 0..1, found {}", u), at);
                if (!ensemble.fcl) cj.fail(path + "fcl_u", "is the uncertainty of a given fcl: give fcl too", at);
                ensemble.fcl_u = u;
            }
            campaign.ensembles[id] = ensemble;
        }
    }
    if (doc.contains("standards")) {
        // Clothing tests: the standard each followed, with its edition (docs/formats.md).
        const auto& st = doc.at("standards");
        const Located at = locate(cj.text(), "\"standards\"");
        if (!st.is_object()) cj.fail("standards", "expected an object: {\"insulation\": \"ISO 15831:2004\", \"evaporative\": ...}", at);
        for (const auto& [test, v] : st.items()) {
            if (test != "insulation" && test != "evaporative")
                cj.fail("standards." + test, "not a clothing test (\"insulation\" or \"evaporative\")", at);
            const std::string standard = cj.string(st, test, "standards.", at);
            if (standard.empty() || standard.size() > 80) cj.fail("standards." + test, "expected 1 to 80 bytes of text", at);
            campaign.standards[test] = standard;
        }
    }
    static const std::set<std::string> known_top{"format", "name", "zone_map", "instruments", "trials", "channels",
                                                 "provenance", "heat_flux_sign", "ensembles", "standards", "notes"};
    for (const auto& [key, value] : doc.items()) {
        (void)value;
        if (!known_top.count(key)) {
            const Located at = locate(cj.text(), "\"" + key + "\"");
            campaign.warnings.push_back(fmt::format("{}:{}:{}: unknown key '{}' ignored", json_file, at.line, at.column, key));
        }
    }

    if (!doc.contains("trials")) cj.fail("trials", "required key is missing");
    const auto& trials = doc.at("trials");
    if (!trials.is_array()) cj.fail("trials", "expected an array of trials", locate(cj.text(), "\"trials\""));
    std::set<std::string> ids;
    std::vector<TrialInfo> infos;
    for (std::size_t i = 0; i < trials.size(); ++i) {
        TrialInfo info = parse_trial_info(trials[i], i, cj, folder, campaign.zone_map, campaign.warnings);
        if (!ids.insert(info.id).second)
            cj.fail(fmt::format("trials[{}].id", i), fmt::format("duplicated trial id '{}'", info.id),
                    locate(cj.text(), "\"" + info.id + "\"", 1));
        infos.push_back(std::move(info));
    }
    // The lab notebook: each note about the campaign or one of its trials, in a known kind.
    if (doc.contains("notes")) {
        const auto& notes = doc.at("notes");
        const Located at = locate(cj.text(), "\"notes\"");
        if (!notes.is_array()) cj.fail("notes", "expected an array of notes", at);
        for (std::size_t i = 0; i < notes.size(); ++i) {
            const auto& n = notes[i];
            const std::string path = fmt::format("notes[{}].", i);
            if (!n.is_object()) cj.fail(fmt::format("notes[{}]", i), "expected an object with utc, author, kind and text", at);
            for (const char* key : {"utc", "author", "kind", "text"})
                if (!n.contains(key)) cj.fail(path + key, "required key is missing", at);
            Note note;
            const std::string utc = cj.string(n, "utc", path, at);
            const auto utc_ns = parse_iso_utc(utc);
            if (!utc_ns) cj.fail(path + "utc", fmt::format("expected ISO 8601 UTC like 2026-11-24T01:35:07.250Z, found '{}'", utc), at);
            note.utc_ns = *utc_ns;
            note.author = cj.string(n, "author", path, at);
            note.kind = cj.string(n, "kind", path, at);
            if (!is_note_kind(note.kind))
                cj.fail(path + "kind", fmt::format("expected comment, operator, ensemble or garment, found '{}'", note.kind), at);
            note.text = cj.string(n, "text", path, at);
            if (note.text.size() > kMaxNoteBytes)
                cj.fail(path + "text", fmt::format("{} bytes, more than a note holds ({})", note.text.size(), kMaxNoteBytes), at);
            if (n.contains("trial")) {
                note.trial = cj.string(n, "trial", path, at);
                if (!ids.count(note.trial)) cj.fail(path + "trial", fmt::format("no trial '{}' in this campaign", note.trial), at);
            }
            campaign.notes.push_back(std::move(note));
        }
    }
    // A trial's ensemble is one the campaign lists (or the bare manikin).
    for (std::size_t i = 0; i < infos.size(); ++i)
        if (!infos[i].ensemble.empty() && infos[i].ensemble != "nude" && !campaign.ensembles.count(infos[i].ensemble))
            cj.fail(fmt::format("trials[{}].ensemble", i),
                    fmt::format("unknown ensemble '{}' (not in the top-level \"ensembles\"; \"nude\" for the bare manikin)",
                                infos[i].ensemble),
                    locate(cj.text(), "\"" + infos[i].ensemble + "\""));
    // Replicate numbers default to the order within a case.
    std::map<int, int> count_per_case;
    std::set<std::pair<int, int>> case_replicates;
    for (auto& info : infos) {
        const int n = ++count_per_case[info.case_id];
        if (info.replicate == 0) info.replicate = n;
        if (!case_replicates.insert({info.case_id, info.replicate}).second)
            campaign.warnings.push_back(fmt::format("{}: trial '{}' repeats replicate {} of case {}", json_file, info.id,
                                                    info.replicate, info.case_id));
    }

    for (auto& info : infos) campaign.trials.push_back({std::move(info), {}});  // samples: read_trial_data
    return campaign;
}

TrialData read_trial_data_checked(const std::filesystem::path& folder, const Campaign& metadata, const TrialInfo& info) {
    const std::filesystem::path csv = folder / info.file;
    return read_trial_csv(csv, metadata.zone_map, csv.string(), metadata.channels);
}

// Every bad input above is an InputError with its field; this net keeps anything missed
// (a filesystem or JSON library error) a bad-input error naming the file, never "internal".
template <typename Read>
auto as_input_error(const std::filesystem::path& folder, Read read) {
    try {
        return read();
    } catch (const InputError&) {
        throw;
    } catch (const std::filesystem::filesystem_error& e) {
        throw InputError(e.path1().empty() ? folder.string() : e.path1().string(), 0, 0, "", e.code().message());
    } catch (const json::exception& e) {
        throw InputError((folder / "campaign.json").string(), 0, 0, "", e.what());
    }
}

}  // namespace

Campaign read_campaign_metadata(const std::filesystem::path& folder, const ReadOptions& options) {
    return as_input_error(folder, [&] { return read_metadata_checked(folder, options); });
}

TrialData read_trial_data(const std::filesystem::path& folder, const Campaign& metadata, const TrialInfo& info) {
    return as_input_error(folder, [&] { return read_trial_data_checked(folder, metadata, info); });
}

Campaign read_campaign(const std::filesystem::path& folder, const ReadOptions& options) {
    return as_input_error(folder, [&] {
        // Parsed into a local campaign and returned only when every file read: never half-imported.
        Campaign campaign = read_metadata_checked(folder, options);
        for (auto& trial : campaign.trials) trial.data = read_trial_data_checked(folder, campaign, trial.info);
        return campaign;
    });
}

}  // namespace manikind::analysis
