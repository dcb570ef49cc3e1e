// config::validate: the checks manikind makes at start, runnable without starting it, so that
// `manikin config check` and the daemon accept and refuse the same files.
#include <sys/un.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <map>
#include <set>

#include <fmt/core.h>

#include "analysis/zone_map.hpp"
#include "archive/pg.hpp"
#include "daemon/config.hpp"
#include "daemon/notifier.hpp"
#include "daemon/web_server.hpp"
#include "drivers/register_map.hpp"
#include "base/user_error.hpp"
#include "sim/campaign/campaign_generator.hpp"
#include "sim/lab/sim_lab.hpp"

namespace manikind::config {
namespace {

// The longest path bind() and connect() take: sun_path less its terminating NUL (107 on Linux).
constexpr std::size_t max_socket_path_chars = sizeof(sockaddr_un{}.sun_path) - 1;
constexpr std::size_t min_token_chars = 24;
constexpr std::size_t min_token_distinct_chars = 10;
constexpr double min_token_bits = 80.0;

// "file:line:column" of a key, or of the nearest thing we know (the file) when it is absent.
std::string where_of(const Config& c, const std::string& key) {
    if (const auto it = c.key_where.find(key); it != c.key_where.end()) return it->second;
    return c.source_name.empty() ? std::string("configuration") : c.source_name;
}

bool set_in_file(const Config& c, const std::string& key) { return c.key_where.count(key) != 0; }

void check_register_maps(const Config& c, std::vector<std::string>& problems) {
    for (const auto& [device, m] : {std::pair<const char*, const ModbusDeviceConfig*>{"chamber", &c.devices.chamber},
                                    {"datalogger", &c.devices.datalogger}}) {
        if (m->register_map == "builtin") continue;
        const std::string key = fmt::format("devices.{}.register_map", device);
        try {
            (void)register_map_from_setting(m->register_map, device, c.source_dir);
        } catch (const UserError& e) {
            problems.push_back(fmt::format("{}: {}: {}", where_of(c, key), key, e.what()));
        }
    }
}

// Each entry is parsed as the simulated lab will parse it at start (acquisition.cpp).
template <typename Parse>
void check_entries(const Config& c, const char* key, const std::vector<std::string>& entries, Parse parse,
                   std::vector<std::string>& problems) {
    for (std::size_t i = 0; i < entries.size(); ++i) {
        const std::string element = fmt::format("{}[{}]", key, i);
        try {
            (void)parse(entries[i]);
        } catch (const std::exception& e) {
            const std::string at = set_in_file(c, element) ? where_of(c, element) : where_of(c, key);
            // Parsers explain on several lines (fault_help); indent them so each problem starts with file:line.
            std::string why = e.what();
            for (std::size_t nl = why.find('\n'); nl != std::string::npos; nl = why.find('\n', nl + 3)) why.insert(nl + 1, "  ");
            problems.push_back(fmt::format("{}: {}: '{}': {}", at, element, entries[i], why));
        }
    }
}

void check_socket(const Config& c, std::vector<std::string>& problems) {
    // The daemon binds the path as given (relative: from its working directory) and writes
    // <socket>.token and takes <socket>.lock beside it; every one must fit in sun_path.
    if (!c.http.listen.empty()) {
        try {
            parse_listen(c.http.listen, where_of(c, "http.listen") + ": http.listen");
        } catch (const UserError& e) {
            problems.push_back(e.what());
        }
    }
    const std::string socket = c.api.socket;
    if (socket.empty()) {
        problems.push_back(fmt::format("{}: api.socket: empty; give the control socket's path", where_of(c, "api.socket")));
        return;
    }
    const std::size_t longest = socket.size() + std::string(".token").size();
    if (longest > max_socket_path_chars)
        problems.push_back(fmt::format(
            "{}: api.socket: '{}' is {} characters, {} with '.token'; a Unix socket path holds at most {} "
            "(sockaddr_un::sun_path, 108 bytes with the NUL), so the socket path must be at most {} characters",
            where_of(c, "api.socket"), socket, socket.size(), longest, max_socket_path_chars,
            max_socket_path_chars - std::string(".token").size()));
}

// mode = "real": a lab's file must say every limit and address itself; the simulated lab's
// defaults (127.0.0.1, /dev/ttyUSB0, its safety limits) are never a real lab's.
void check_real_mode(const Config& c, std::vector<std::string>& problems) {
    const std::string at = where_of(c, "lab.mode");
    static const std::array<const char*, 9> safety_keys = {
        "max_skin_temp_c",    "min_skin_temp_c",    "max_heater_temp_c",  "max_heater_power_w_m2", "min_chamber_temp_c",
        "max_chamber_temp_c", "min_chamber_rh_pct", "max_chamber_rh_pct", "watchdog_timeout_s"};
    std::string missing;
    for (const char* k : safety_keys)
        if (!set_in_file(c, std::string("safety.") + k)) missing += (missing.empty() ? "" : ", ") + std::string(k);
    if (!missing.empty())
        problems.push_back(fmt::format("{}: safety: mode = \"real\" needs every [safety] limit set in the file; missing: {}",
                                       at, missing));
    const auto require = [&](const std::string& key, const std::string& value, const char* what) {
        if (!set_in_file(c, key) || value.empty())
            problems.push_back(fmt::format("{}: {}: mode = \"real\" needs {} set in the file", at, key, what));
    };
    require("lab.database", c.database.string(), "the database path");
    for (const auto& [device, m] : {std::pair<const char*, const ModbusDeviceConfig*>{"chamber", &c.devices.chamber},
                                    {"datalogger", &c.devices.datalogger}}) {
        const std::string base = std::string("devices.") + device;
        const bool host = set_in_file(c, base + ".host") && !m->host.empty();
        const bool serial = set_in_file(c, base + ".serial") && !m->serial.empty();
        if (!host && !serial)
            problems.push_back(fmt::format("{}: {}: mode = \"real\" needs host (Modbus TCP) or serial (RTU) set in the file",
                                           at, base));
    }
    require("devices.windsonic.path", c.devices.windsonic_path, "the WindSonic's serial device");
    require("devices.csat3b.path", c.devices.csat3b_path, "the CSAT3B's serial device");
    require("devices.manikin.interface", c.devices.manikin_interface, "the manikin's CAN interface");
    require("api.token", c.api.token, "the API token (make one with `manikin config token`)");
}

}  // namespace

// Limits that fit the hardware (issue 31): a limit the configured devices reach in normal
// operation trips at once; standby must be a setpoint the daemon may send.
void check_limits_fit_devices(const Config& c, std::vector<std::string>& problems) {
    const auto& l = c.safety;
    const double rating = c.devices.manikin_max_heater_power_w_m2;
    if (l.max_heater_power_w_m2 < rating)
        problems.push_back(fmt::format(
            "{}: safety.max_heater_power_w_m2 = {} W/m² is below the manikin's heater rating "
            "(devices.manikin.max_heater_power_w_m2 = {} W/m²): every cold start drives the heaters to their rating, so "
            "the first seconds of every trial would stop heating and abort the campaign. Set it at or above {} W/m² (the "
            "heaters cannot exceed their rating: the limit then catches a reading the hardware cannot make), or give the "
            "manikin's true rating",
            where_of(c, "safety.max_heater_power_w_m2"), l.max_heater_power_w_m2, rating, rating));
    if (l.min_skin_temp_c >= l.max_skin_temp_c)
        problems.push_back(fmt::format("{}: safety.min_skin_temp_c = {} °C is not below max_skin_temp_c = {} °C",
                                       where_of(c, "safety.min_skin_temp_c"), l.min_skin_temp_c, l.max_skin_temp_c));
    const auto& ph = c.physiological;
    if (ph.min_skin_setpoint_c < l.min_skin_temp_c || ph.max_skin_setpoint_c > l.max_skin_temp_c)
        problems.push_back(fmt::format("{}: physiological skin setpoints {}..{} °C reach outside the safety limits {}..{} °C "
                                       "(safety.min/max_skin_temp_c): the model could ask for a skin the daemon must stop",
                                       where_of(c, "physiological"), ph.min_skin_setpoint_c, ph.max_skin_setpoint_c,
                                       l.min_skin_temp_c, l.max_skin_temp_c));
    const auto& sb = c.standby;
    if (sb.chamber_temp_c < l.min_chamber_temp_c || sb.chamber_temp_c > l.max_chamber_temp_c)
        problems.push_back(fmt::format("{}: standby.chamber_temp_c = {} °C is outside the safety limits {}..{} °C",
                                       where_of(c, "standby.chamber_temp_c"), sb.chamber_temp_c, l.min_chamber_temp_c,
                                       l.max_chamber_temp_c));
    if (sb.chamber_rh_pct < l.min_chamber_rh_pct || sb.chamber_rh_pct > l.max_chamber_rh_pct)
        problems.push_back(fmt::format("{}: standby.chamber_rh_pct = {} % is outside the safety limits {}..{} %",
                                       where_of(c, "standby.chamber_rh_pct"), sb.chamber_rh_pct, l.min_chamber_rh_pct,
                                       l.max_chamber_rh_pct));
}

namespace {

void check_token(const Config& c, std::vector<std::string>& problems) {
    if (c.api.token.empty()) return;  // the daemon makes one (<socket>.token, 0600)
    if (const auto why = token_problem(c.api.token); !why.empty())
        problems.push_back(fmt::format("{}: api.token: {}", where_of(c, "api.token"), why));
    if (set_in_file(c, "api.token") && c.file_mode != 0 && (c.file_mode & 0004) != 0)
        problems.push_back(fmt::format("{}: holds the API token but is readable by every user (mode {:04o}): chmod 640 {}",
                                       c.source_name, c.file_mode & 07777, c.source_name));
}

// [notifications]: known event kinds, URLs of the schemes libcurl is allowed here, an e-mail with
// a sender and plain addresses (no header can be smuggled in through one).
void check_notifications(const Config& c, std::vector<std::string>& problems) {
    const auto& n = c.notifications;
    for (std::size_t i = 0; i < n.events.size(); ++i)
        if (!notice_kinds().count(n.events[i])) {
            std::string list;
            for (const auto& k : notice_kinds()) list += (list.empty() ? "" : ", ") + k;
            problems.push_back(fmt::format("{}: notifications.events: '{}' is not one of {}",
                                           where_of(c, fmt::format("notifications.events[{}]", i)), n.events[i], list));
        }
    auto scheme_ok = [](const std::string& url, std::initializer_list<const char*> schemes) {
        for (const char* s : schemes)
            if (url.rfind(s, 0) == 0 && url.size() > std::string(s).size()) return true;
        return false;
    };
    if (!n.webhook_url.empty() && !scheme_ok(n.webhook_url, {"http://", "https://"}))
        problems.push_back(fmt::format("{}: notifications.webhook_url: expected http://... or https://..., found '{}'",
                                       where_of(c, "notifications.webhook_url"), n.webhook_url));
    if (!n.smtp_url.empty() && !scheme_ok(n.smtp_url, {"smtp://", "smtps://"}))
        problems.push_back(fmt::format("{}: notifications.smtp_url: expected smtp://host:port or smtps://host:port, found '{}'",
                                       where_of(c, "notifications.smtp_url"), n.smtp_url));
    if (!n.smtp_url.empty() && (n.mail_from.empty() || n.mail_to.empty()))
        problems.push_back(fmt::format("{}: notifications: an smtp_url needs mail_from and at least one mail_to",
                                       where_of(c, "notifications.smtp_url")));
    auto plain_address = [](const std::string& a) {
        const auto at = a.find('@');
        return at != std::string::npos && at > 0 && at + 1 < a.size() && a.size() <= 254 &&
               std::all_of(a.begin(), a.end(), [](char ch) { return ch > ' ' && ch < 127 && ch != '<' && ch != '>' && ch != ','; });
    };
    if (!n.mail_from.empty() && !plain_address(n.mail_from))
        problems.push_back(fmt::format("{}: notifications.mail_from: expected a plain address like manikind@lab.example, found '{}'",
                                       where_of(c, "notifications.mail_from"), n.mail_from));
    for (std::size_t i = 0; i < n.mail_to.size(); ++i)
        if (!plain_address(n.mail_to[i]))
            problems.push_back(fmt::format("{}: notifications.mail_to: expected a plain address like ana@lab.example, found '{}'",
                                           where_of(c, fmt::format("notifications.mail_to[{}]", i)), n.mail_to[i]));
}

// [archive]: a conninfo libpq parses, a lab id the archive accepts, no password in a file every
// user can read (docs/archive.md).
void check_archive(const Config& c, std::vector<std::string>& problems) {
    const auto& a = c.archive;
    if (a.postgresql.empty()) {
        if (!a.lab_id.empty())
            problems.push_back(fmt::format("{}: archive.lab_id: set, but archive.postgresql is empty: nothing would "
                                           "be forwarded; give the archive's connection string",
                                           where_of(c, "archive.lab_id")));
        return;
    }
    const auto parsed = archive::PgConnection::parse_conninfo(a.postgresql);
    if (!parsed.error.empty()) {
        problems.push_back(fmt::format("{}: archive.postgresql: does not parse as a libpq connection string or URI: {}",
                                       where_of(c, "archive.postgresql"), parsed.error));
    } else if (parsed.has_password && set_in_file(c, "archive.postgresql") && c.file_mode != 0 && (c.file_mode & 0004) != 0) {
        problems.push_back(fmt::format("{}: archive.postgresql holds a password but the file is readable by every "
                                       "user (mode {:04o}): chmod 640 {}, or move the password to ~/.pgpass",
                                       c.source_name, c.file_mode & 07777, c.source_name));
    }
    const bool ok_chars = std::all_of(a.lab_id.begin(), a.lab_id.end(), [](char ch) {
        return std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_' || ch == '.';
    });
    if (a.lab_id.empty())
        problems.push_back(fmt::format("{}: archive.lab_id: needed with archive.postgresql: this lab's key in the "
                                       "archive (1 to 64 letters, digits, '-', '_' or '.'), the same at every push",
                                       where_of(c, "archive")));
    else if (a.lab_id.size() > 64 || !ok_chars)
        problems.push_back(fmt::format("{}: archive.lab_id: '{}': expected 1 to 64 letters, digits, '-', '_' or '.'",
                                       where_of(c, "archive.lab_id"), a.lab_id));
}

}  // namespace

std::string token_problem(const std::string& token) {
    static const char* const how = "make one with `manikin config token` (or `openssl rand -hex 32`)";
    std::string lower(token);
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    for (const char* word : {"change-me", "changeme", "example", "placeholder", "your-token", "secret", "password"})
        if (lower.find(word) != std::string::npos)
            return fmt::format("is a placeholder (contains '{}'), refused until replaced; {}", word, how);
    if (token.size() < min_token_chars)
        return fmt::format("is {} characters, fewer than {}; {}", token.size(), min_token_chars, how);
    std::map<char, std::size_t> counts;
    for (const char ch : token) ++counts[ch];
    if (counts.size() < min_token_distinct_chars)
        return fmt::format("has only {} distinct characters (at least {}); {}", counts.size(), min_token_distinct_chars, how);
    // Shannon estimate: length x the per-character entropy of the token's own character frequencies.
    double bits_per_char = 0.0;
    for (const auto& [ch, n] : counts) {
        const double p = static_cast<double>(n) / static_cast<double>(token.size());
        bits_per_char -= p * std::log2(p);
    }
    const double bits = bits_per_char * static_cast<double>(token.size());
    if (bits < min_token_bits)
        return fmt::format("carries about {:.0f} bits by its character statistics (at least {:.0f}); {}", bits, min_token_bits, how);
    return {};
}

namespace {
// [[simulation.local]]: every name it gives is a zone, region or segment of the zone map the
// simulated manikin wears (simulated_lab.cpp resolves them the same way at start).
void check_local_environment(const Config& c, std::vector<std::string>& problems) {
    const auto& map = analysis::andi35_zone_map();
    for (std::size_t i = 0; i < c.simulation.local.size(); ++i)
        for (const auto& name : c.simulation.local[i].zones)
            if (map.zones_named(name).empty())
                problems.push_back(fmt::format("{}: simulation.local[{}].zones: '{}' is no zone, region or segment of the zone map "
                                               "(config/andi35_zone_map.csv)", c.simulation.local[i].where, i, name));
}
}  // namespace

std::vector<std::string> validate(const Config& c) {
    std::vector<std::string> problems;
    check_register_maps(c, problems);
    check_entries(c, "simulation.world_effects", c.simulation.world_effects, sim::parse_effect, problems);
    check_entries(c, "simulation.faults", c.simulation.faults, sim::parse_fault, problems);
    check_local_environment(c, problems);
    check_socket(c, problems);
    if (c.mode == "real") check_real_mode(c, problems);
    check_token(c, problems);
    check_archive(c, problems);
    check_notifications(c, problems);
    check_limits_fit_devices(c, problems);
    return problems;
}

void require_valid(const Config& c) {
    const auto problems = validate(c);
    if (problems.empty()) return;
    std::string text;
    for (const auto& p : problems) text += (text.empty() ? "" : "\n") + p;
    throw UserError(text);
}

}  // namespace manikind::config
