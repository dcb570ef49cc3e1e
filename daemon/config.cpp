#include "daemon/config.hpp"
#include "base/sha256.hpp"

#include <sys/stat.h>

#include <set>

#include <fmt/core.h>
#include <toml++/toml.h>

#include "analysis/local_room.hpp"
#include "base/toml_input.hpp"
#include "base/user_error.hpp"

namespace manikind::config {
namespace {

using toml_input::where;

std::string type_name(const toml::node& node) {
    switch (node.type()) {
        case toml::node_type::string: return "a string";
        case toml::node_type::integer: return "an integer";
        case toml::node_type::floating_point: return "a number";
        case toml::node_type::boolean: return "a boolean";
        case toml::node_type::table: return "a table";
        case toml::node_type::array: return "an array";
        default: return "a date or time";
    }
}

class Reader {
public:
    Reader(std::string source, Config& out) : source_(std::move(source)), out_(out) {}

    void number(const toml::table& table, const std::string& path, const char* key, double& value, double lo, double hi,
                const char* unit) {
        mark(path, key);
        const toml::node* node = table.get(key);
        if (!node) return;
        const std::string full = path.empty() ? key : path + "." + key;
        if (!node->is_number())
            throw UserError(fmt::format("{}: {}: expected a number ({}), found {}", where(source_, node->source()), full,
                                        unit, type_name(*node)));
        const double v = node->is_integer() ? static_cast<double>(node->as_integer()->get()) : node->as_floating_point()->get();
        if (!(v >= lo && v <= hi))
            throw UserError(fmt::format("{}: {}: {} {} is outside {}..{} {}", where(source_, node->source()), full, v, unit,
                                        lo, hi, unit));
        value = v;
    }

    void text(const toml::table& table, const std::string& path, const char* key, std::string& value,
              const std::set<std::string>& allowed = {}) {
        mark(path, key);
        const toml::node* node = table.get(key);
        if (!node) return;
        const std::string full = path.empty() ? key : path + "." + key;
        if (!node->is_string())
            throw UserError(fmt::format("{}: {}: expected a string, found {}", where(source_, node->source()), full,
                                        type_name(*node)));
        std::string v = node->as_string()->get();
        if (!allowed.empty() && !allowed.count(v)) {
            std::string list;
            for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
            throw UserError(fmt::format("{}: {}: '{}' is not one of {}", where(source_, node->source()), full, v, list));
        }
        value = std::move(v);
    }

    const toml::table* table(const toml::table& parent, const std::string& path, const char* key) {
        mark(path, key);
        const toml::node* node = parent.get(key);
        if (!node) return nullptr;
        if (!node->is_table())
            throw UserError(fmt::format("{}: {}: expected a table, found {}", where(source_, node->source()),
                                        path.empty() ? key : path + "." + key, type_name(*node)));
        return node->as_table();
    }

    void strings(const toml::table& table, const std::string& path, const char* key, std::vector<std::string>& value) {
        mark(path, key);
        const toml::node* node = table.get(key);
        if (!node) return;
        const std::string full = path.empty() ? key : path + "." + key;
        const auto* arr = node->as_array();
        if (!arr) throw UserError(fmt::format("{}: {}: expected an array of strings, found {}", where(source_, node->source()), full, type_name(*node)));
        value.clear();
        for (const auto& item : *arr) {
            if (!item.is_string())
                throw UserError(fmt::format("{}: {}: expected strings, found {}", where(source_, item.source()), full, type_name(item)));
            value.push_back(item.as_string()->get());
        }
    }

    void mark(const std::string& path, const std::string& key) { known_.insert(path.empty() ? key : path + "." + key); }

    // Anything present in the file that no reader asked for.
    void warn_unknown(const toml::table& table, const std::string& path) {
        for (const auto& [key, node] : table) {
            const std::string full = path.empty() ? std::string(key.str()) : path + "." + std::string(key.str());
            if (!known_.count(full)) {
                out_.warnings.push_back(fmt::format("{}: {}: unknown key, ignored", where(source_, node.source()), full));
            } else if (node.is_table() && path != "instruments") {
                warn_unknown(*node.as_table(), full);
            }
        }
    }

    // Every key in the text and where it is, so later checks can name the line.
    void record_positions(const toml::table& table, const std::string& path) {
        for (const auto& [key, node] : table) {
            const std::string full = path.empty() ? std::string(key.str()) : path + "." + std::string(key.str());
            out_.key_where[full] = where(source_, node.source());
            if (const auto* t = node.as_table()) record_positions(*t, full);
            if (const auto* a = node.as_array())
                for (std::size_t i = 0; i < a->size(); ++i)
                    out_.key_where[fmt::format("{}[{}]", full, i)] = where(source_, (*a)[i].source());
        }
    }

private:
    std::string source_;
    Config& out_;
    std::set<std::string> known_;
};

}  // namespace

Config default_config() {
    static const Config parsed = parse_config(default_config_toml(), "config/manikind.toml (built in)", Config{});
    return parsed;
}

Config parse_config(const std::string& toml_text, const std::string& source_name) {
    return parse_config(toml_text, source_name, default_config());
}

Config parse_config(const std::string& toml_text, const std::string& source_name, const Config& base) {
    const toml::table root = toml_input::parse(toml_text, source_name);
    Config c = base;
    c.warnings.clear();
    c.key_where.clear();
    c.source_name = source_name;
    c.file_mode = 0;
    c.source_sha256 = sha256_hex(toml_text);
    c.source_text = toml_text;
    Reader r(source_name, c);
    r.record_positions(root, "");
    if (const auto* lab = r.table(root, "", "lab")) {
        r.text(*lab, "lab", "name", c.lab_name);
        r.text(*lab, "lab", "mode", c.mode, {"simulated", "real"});
        std::string db = c.database.string();
        r.text(*lab, "lab", "database", db);
        c.database = db;
        r.number(*lab, "lab", "idle_log_period_s", c.idle_log_period_s, 0.0, 3600.0, "s");
        r.text(*lab, "lab", "chamber", c.chamber);
        r.text(*lab, "lab", "manikin", c.manikin);
    }
    // The built-in file names the simulated chamber and manikin; a real lab's file names its own
    // or says nothing, and then its trials record no instrument rather than the simulated one.
    if (c.mode == "real") {
        for (auto [key, value] : {std::pair{"chamber", &c.chamber}, std::pair{"manikin", &c.manikin}}) {
            if (c.key_where.count(std::string("lab.") + key)) continue;
            *value = "";
            c.warnings.push_back(fmt::format("{}: [lab] {} is not set: trials will not record which {} they ran in "
                                             "(make, model, serial number)",
                                             source_name, key, key));
        }
    }
    if (const auto* log = r.table(root, "", "logging"))
        r.text(*log, "logging", "level", c.log_level, {"trace", "debug", "info", "warn", "error"});
    if (const auto* s = r.table(root, "", "safety")) {
        SafetyLimits& l = c.safety;
        r.number(*s, "safety", "max_skin_temp_c", l.max_skin_temp_c, 0.0, 60.0, "°C");
        r.number(*s, "safety", "min_skin_temp_c", l.min_skin_temp_c, 0.0, 60.0, "°C");
        r.number(*s, "safety", "max_heater_temp_c", l.max_heater_temp_c, 0.0, 80.0, "°C");
        r.number(*s, "safety", "max_heater_power_w_m2", l.max_heater_power_w_m2, 0.0, 2000.0, "W/m²");
        r.number(*s, "safety", "min_chamber_temp_c", l.min_chamber_temp_c, -40.0, 80.0, "°C");
        r.number(*s, "safety", "max_chamber_temp_c", l.max_chamber_temp_c, -40.0, 80.0, "°C");
        r.number(*s, "safety", "min_chamber_rh_pct", l.min_chamber_rh_pct, 0.0, 100.0, "%");
        r.number(*s, "safety", "max_chamber_rh_pct", l.max_chamber_rh_pct, 0.0, 100.0, "%");
        r.number(*s, "safety", "watchdog_timeout_s", l.watchdog_timeout_s, 0.1, 3600.0, "s");
        if (l.min_skin_temp_c >= l.max_skin_temp_c || l.min_chamber_temp_c >= l.max_chamber_temp_c ||
            l.min_chamber_rh_pct >= l.max_chamber_rh_pct)
            throw UserError(fmt::format("{}: [safety]: every min_* must be below its max_*", source_name));
    }
    if (const auto* s = r.table(root, "", "steady_state")) {
        double window_min = c.steady_state.window_s / 60.0;
        r.number(*s, "steady_state", "window_min", window_min, 1.0, 600.0, "min");
        c.steady_state.window_s = window_min * 60.0;
        r.number(*s, "steady_state", "max_skin_fluctuation_c", c.steady_state.max_skin_fluctuation_c, 0.001, 5.0, "°C");
    }
    if (const auto* inst = r.table(root, "", "instruments")) {
        for (const auto& [key, node] : *inst) {
            const std::string channel(key.str());
            const auto* t = r.table(*inst, "instruments", channel.c_str());
            InstrumentSpec spec;
            const std::string path = "instruments." + channel;
            r.number(*t, path, "accuracy", spec.accuracy, 0.0, 1e6, "channel unit");
            r.number(*t, path, "accuracy_of_reading", spec.accuracy_of_reading, 0.0, 1.0, "fraction");
            r.text(*t, path, "distribution", spec.distribution, {"rectangular", "normal"});
            r.warn_unknown(*t, path);
            c.instruments[channel] = spec;
        }
    }
    if (const auto* d = r.table(root, "", "devices")) {
        DeviceConfig& dc = c.devices;
        for (auto [key, m] : {std::pair<const char*, ModbusDeviceConfig*>{"chamber", &dc.chamber}, {"datalogger", &dc.datalogger}})
            if (const auto* t = r.table(*d, "devices", key)) {
                const std::string path = std::string("devices.") + key;
                r.text(*t, path, "host", m->host);
                r.number(*t, path, "port", m->port, 1, 65535, "");
                r.text(*t, path, "serial", m->serial);
                r.number(*t, path, "baud", m->baud, 1200, 921600, "baud");
                r.text(*t, path, "register_map", m->register_map);
                r.number(*t, path, "max_gap_registers", m->max_gap_registers, 0, 124, "registers");
                r.number(*t, path, "requests_in_flight", m->requests_in_flight, 1, 16, "requests");
            }
        if (const auto* t = r.table(*d, "devices", "windsonic")) {
            r.text(*t, "devices.windsonic", "path", dc.windsonic_path);
            r.number(*t, "devices.windsonic", "baud", dc.windsonic_baud, 1200, 921600, "baud");
        }
        if (const auto* t = r.table(*d, "devices", "csat3b")) {
            r.text(*t, "devices.csat3b", "path", dc.csat3b_path);
            r.number(*t, "devices.csat3b", "baud", dc.csat3b_baud, 1200, 921600, "baud");
        }
        if (const auto* t = r.table(*d, "devices", "manikin")) {
            r.text(*t, "devices.manikin", "interface", dc.manikin_interface);
            r.text(*t, "devices.manikin", "capture", dc.manikin_capture);
            r.number(*t, "devices.manikin", "max_heater_power_w_m2", dc.manikin_max_heater_power_w_m2, 10.0, 2000.0, "W/m²");
        }
        r.number(*d, "devices", "modbus_timeout_s", dc.modbus_timeout_s, 0.01, 30.0, "s");
        r.number(*d, "devices", "poll_period_s", dc.poll_period_s, 0.05, 3600.0, "s");
        r.number(*d, "devices", "stale_after_s", dc.stale_after_s, 0.1, 3600.0, "s");
    }
    if (const auto* s = r.table(root, "", "simulation")) {
        double seed = static_cast<double>(c.simulation.seed);
        r.number(*s, "simulation", "seed", seed, 0, 9007199254740992.0, "");
        c.simulation.seed = static_cast<std::uint64_t>(seed);
        r.strings(*s, "simulation", "world_effects", c.simulation.world_effects);
        r.strings(*s, "simulation", "faults", c.simulation.faults);
        r.text(*s, "simulation", "runtime_dir", c.simulation.runtime_dir);
        r.number(*s, "simulation", "step_s", c.simulation.step_s, 0.01, 60.0, "s");
        r.number(*s, "simulation", "manikin_period_s", c.simulation.manikin_period_s, 0.1, 60.0, "s");
        r.number(*s, "simulation", "air_speed_m_s", c.simulation.air_speed_m_s, 0.0, 5.0, "m/s");
        r.number(*s, "simulation", "wall_below_air_c", c.simulation.wall_below_air_c, -10.0, 10.0, "K");
        r.text(*s, "simulation", "operator_prompts", c.simulation.operator_prompts, {"auto", "wait"});
        sim::ReplicateScatter& sc = c.simulation.scatter;
        r.number(*s, "simulation", "replicate_flux_rel_sd", sc.replicate_flux_rel_sd, 0.0, 0.2, "fraction");
        r.number(*s, "simulation", "replicate_flux_sd_w_m2", sc.replicate_flux_sd_w_m2, 0.0, 50.0, "W/m²");
        r.number(*s, "simulation", "replicate_air_sd_c", sc.replicate_air_sd_c, 0.0, 5.0, "°C");
        r.number(*s, "simulation", "replicate_rh_sd_pct", sc.replicate_rh_sd_pct, 0.0, 20.0, "%");
        r.number(*s, "simulation", "replicate_wall_sd_c", sc.replicate_wall_sd_c, 0.0, 5.0, "°C");
        r.number(*s, "simulation", "probe_air_sd_c", sc.probe_air_sd_c, 0.0, 5.0, "°C");
        r.number(*s, "simulation", "probe_rh_sd_pct", sc.probe_rh_sd_pct, 0.0, 20.0, "%");
        r.number(*s, "simulation", "probe_wall_sd_c", sc.probe_wall_sd_c, 0.0, 5.0, "°C");
        r.mark("simulation", "local");
        if (const toml::node* node = s->get("local")) {
            const auto* arr = node->as_array();
            if (!arr || !arr->is_array_of_tables())
                throw UserError(fmt::format("{}: simulation.local: expected [[simulation.local]] tables, found {}",
                                            where(source_name, node->source()), type_name(*node)));
            c.simulation.local.clear();
            for (std::size_t i = 0; i < arr->size(); ++i) {
                const toml::table& t = *(*arr)[i].as_table();
                const std::string path = fmt::format("simulation.local[{}]", i);
                LocalEnvironmentConfig e;
                e.where = where(source_name, t.source());
                r.strings(t, path, "zones", e.zones);
                if (e.zones.empty())
                    throw UserError(fmt::format("{}: {}.zones: expected the zones, regions or segments it applies to "
                                                "(e.g. zones = [\"face\", \"hand_l\"])", e.where, path));
                r.text(t, path, "what", e.what);
                auto number = [&](const char* key, auto& out) {
                    const auto& range = analysis::local_range(key);
                    r.number(t, path, key, out, range.lo, range.hi, range.unit);
                };
                number("air_offset_c", e.air_offset_c);
                number("radiant_offset_c", e.radiant_offset_c);
                number("air_speed_m_s", e.air_speed_m_s);
                number("contact_w_m2", e.contact_w_m2);
                number("solar_w_m2", e.solar_w_m2);
                r.warn_unknown(t, path);
                c.simulation.local.push_back(std::move(e));
            }
        }
    }
    if (const auto* a = r.table(root, "", "api")) {
        r.text(*a, "api", "socket", c.api.socket);
        r.number(*a, "api", "tcp_port", c.api.tcp_port, 0, 65535, "");
        r.text(*a, "api", "token", c.api.token);
        r.number(*a, "api", "max_clients", c.api.max_clients, 1, 4096, "clients");
        r.number(*a, "api", "idle_timeout_s", c.api.idle_timeout_s, 1, 86400, "s");
        r.number(*a, "api", "partial_grace_s", c.api.partial_grace_s, 0.05, 60, "s");
        r.number(*a, "api", "max_clients_per_peer", c.api.max_clients_per_peer, 0, 4096, "clients");
    }
    if (const auto* h = r.table(root, "", "http")) r.text(*h, "http", "listen", c.http.listen);
    if (const auto* s = r.table(root, "", "standby")) {
        r.number(*s, "standby", "chamber_temp_c", c.standby.chamber_temp_c, -40.0, 100.0, "°C");
        r.number(*s, "standby", "chamber_rh_pct", c.standby.chamber_rh_pct, 0.0, 100.0, "%");
    }
    if (const auto* rec = r.table(root, "", "recorder")) {
        r.text(*rec, "recorder", "durability", c.recorder_durability, {"process", "power"});
        r.number(*rec, "recorder", "commit_interval_s", c.recorder_commit_interval_s, 0.05, 60.0, "s");
        r.text(*rec, "recorder", "crash_ring_dir", c.recorder_crash_ring_dir);
        r.text(*rec, "recorder", "journal", c.recorder_journal, {"wal", "rollback"});
        r.number(*rec, "recorder", "lock_timeout_s", c.recorder_lock_timeout_s, 0.001, 600.0, "s");
    }
    if (const auto* a = r.table(root, "", "archive")) {
        r.text(*a, "archive", "postgresql", c.archive.postgresql);
        r.text(*a, "archive", "lab_id", c.archive.lab_id);
        r.text(*a, "archive", "lab_name", c.archive.lab_name);
        r.number(*a, "archive", "interval_s", c.archive.interval_s, 0.5, 3600.0, "s");
    }
    if (const auto* n = r.table(root, "", "notifications")) {
        auto& x = c.notifications;
        r.strings(*n, "notifications", "events", x.events);
        r.text(*n, "notifications", "webhook_url", x.webhook_url);
        r.text(*n, "notifications", "webhook_format", x.webhook_format, {"json", "slack", "matrix"});
        r.text(*n, "notifications", "smtp_url", x.smtp_url);
        r.text(*n, "notifications", "mail_from", x.mail_from);
        r.strings(*n, "notifications", "mail_to", x.mail_to);
        r.number(*n, "notifications", "min_interval_s", x.min_interval_s, 0.0, 86400.0, "s");
        r.number(*n, "notifications", "retries", x.retries, 0.0, 10.0, "tries");
        r.number(*n, "notifications", "timeout_s", x.timeout_s, 0.5, 120.0, "s");
    }
    if (const auto* ph = r.table(root, "", "physiological")) {
        auto& p = c.physiological;
        r.number(*ph, "physiological", "coupling_period_s", p.coupling_period_s, 1.0, 600.0, "s");
        r.number(*ph, "physiological", "max_setpoint_rate_c_min", p.max_setpoint_rate_c_min, 0.01, 10.0, "°C/min");
        r.number(*ph, "physiological", "min_skin_setpoint_c", p.min_skin_setpoint_c, 20.0, 45.0, "°C");
        r.number(*ph, "physiological", "max_skin_setpoint_c", p.max_skin_setpoint_c, 20.0, 45.0, "°C");
        r.number(*ph, "physiological", "max_sweat_rate_g_m2_h", p.max_sweat_rate_g_m2_h, 0.0, 2000.0, "g/m²/h");
        r.number(*ph, "physiological", "follow_tolerance_c", p.follow_tolerance_c, 0.05, 10.0, "°C");
        r.number(*ph, "physiological", "follow_timeout_s", p.follow_timeout_s, 1.0, 7200.0, "s");
        r.number(*ph, "physiological", "stale_after_s", p.stale_after_s, 1.0, 3600.0, "s");
        r.number(*ph, "physiological", "min_core_temp_c", p.min_core_temp_c, 30.0, 45.0, "°C");
        r.number(*ph, "physiological", "max_core_temp_c", p.max_core_temp_c, 30.0, 45.0, "°C");
        r.number(*ph, "physiological", "shell_heat_capacity_j_m2k", p.shell_heat_capacity_j_m2k, 0.0, 1e6, "J/(m²K)");
        r.number(*ph, "physiological", "shell_heat_capacity_u_j_m2k", p.shell_heat_capacity_u_j_m2k, 0.0, 1e6, "J/(m²K)");
        if (p.min_skin_setpoint_c >= p.max_skin_setpoint_c || p.min_core_temp_c >= p.max_core_temp_c)
            throw UserError(fmt::format("{}: [physiological]: every min_* must be below its max_*", source_name));
        if (const auto* seg = r.table(*ph, "physiological", "segments")) {
            static const std::set<std::string> model_segments = {"head", "trunk", "arms", "hands", "legs", "feet"};
            std::map<std::string, std::vector<std::string>> map;
            for (const auto& [key, node] : *seg) {
                const std::string name(key.str());
                if (!model_segments.count(name))
                    throw UserError(fmt::format("{}: physiological.segments.{}: not a model segment (head, trunk, arms, "
                                                "hands, legs, feet)",
                                                where(source_name, node.source()), name));
                r.strings(*seg, "physiological.segments", name.c_str(), map[name]);
            }
            if (map.size() != model_segments.size())
                throw UserError(fmt::format("{}: physiological.segments: give all six model segments (head, trunk, arms, "
                                            "hands, legs, feet), each with its zone-map segments",
                                            where(source_name, seg->source())));
            p.segments = std::move(map);
        }
    }
    r.warn_unknown(root, "");
    return c;
}

Config load_config(const std::filesystem::path& path) {
    const std::string text = toml_input::read_text_file(path, "a TOML configuration file");
    Config c = parse_config(text, path.string());
    c.source_dir = path.parent_path();
    // Kept for validate(): a file holding the API token must not be readable by every user.
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0) c.file_mode = static_cast<unsigned>(st.st_mode & 07777);
    return c;
}

}  // namespace manikind::config
