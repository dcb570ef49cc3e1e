#include "daemon/console_model.hpp"

#include <fmt/format.h>

#include <cmath>

#include "analysis/zone_map.hpp"
#include "analysis/reconcile/twin_store.hpp"
#include "physics/twin/twin.hpp"

namespace manikind::console {

const char* to_string(Severity s) {
    switch (s) {
        case Severity::no_alarm: return "NO_ALARM";
        case Severity::minor: return "MINOR";
        case Severity::major: return "MAJOR";
        case Severity::invalid: return "INVALID";
    }
    return "INVALID";
}

namespace {

std::uint64_t counter(const nlohmann::json& d, const char* key) {
    return d.contains(key) && d[key].is_number_unsigned() ? d[key].get<std::uint64_t>() : 0;
}

// Label values escape backslash, double quote and newline (exposition format 0.0.4).
std::string label(const std::string& v) {
    std::string out;
    for (char c : v) {
        if (c == '\\') out += "\\\\";
        else if (c == '"') out += "\\\"";
        else if (c == '\n') out += "\\n";
        else out += c;
    }
    return out;
}

std::string number(double v) {
    if (std::isnan(v)) return "NaN";
    if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
    return fmt::format("{}", v);
}

}  // namespace

void DeviceSeverity::annotate(nlohmann::json& devices, double now_s) {
    for (auto& d : devices) {
        const std::string name = d.value("name", std::string("?"));
        const std::uint64_t errors = counter(d, "checksum_errors") + counter(d, "timeouts") + counter(d, "exceptions") +
                                     counter(d, "malformed") + counter(d, "device_faults");
        const auto seen = last_errors_.find(name);
        if (seen != last_errors_.end() && errors > seen->second) last_rise_s_[name] = now_s;
        last_errors_[name] = errors;
        Severity s = Severity::no_alarm;
        std::string why;
        if (!d.value("connected", false)) {
            s = Severity::invalid;
            why = "not connected";
        } else if (d.value("stale", false)) {
            s = Severity::major;
            why = "values stale";
        } else if (const auto rise = last_rise_s_.find(name); rise != last_rise_s_.end() && now_s - rise->second <= minor_hold_s_) {
            s = Severity::minor;
            why = fmt::format("errors in the last {:.0f} s", minor_hold_s_);
        }
        d["severity"] = to_string(s);
        d["severity_level"] = static_cast<int>(s);
        d["severity_reason"] = why;
    }
}

void ChamberHistory::add(double now_s, std::int64_t utc_ms, const nlohmann::json& live, const nlohmann::json& status) {
    // The spans' starts follow the daemon's trial and campaign, whatever the step.
    if (status.is_object()) {
        const auto& trial = status.contains("trial") ? status["trial"] : nlohmann::json();
        const std::int64_t id = trial.is_object() && trial.contains("id") && trial["id"].is_number_integer() ? trial["id"].get<std::int64_t>() : 0;
        if (id != 0 && id != trial_id_) {
            trial_id_ = id;
            trial_start_utc_ms_ = utc_ms;
        }
        const auto& c = status.contains("campaign") ? status["campaign"] : nlohmann::json();
        if (c.is_string() && c.get<std::string>() != campaign_) {
            campaign_ = c.get<std::string>();
            const auto known = campaign_starts_.find(campaign_);
            campaign_start_utc_ms_ = known != campaign_starts_.end() ? known->second : utc_ms;
        }
    }
    if (now_s - last_s_ < step_s_) return;
    last_s_ = now_s;
    constexpr double nan = std::numeric_limits<double>::quiet_NaN();
    auto value = [&](const char* key) {
        if (!live.contains(key) || !live[key].contains("value") || !live[key]["value"].is_number()) return nan;
        return live[key]["value"].get<double>();
    };
    // The setpoint the daemon last sent (status.measured), where the register is not read back.
    auto sent = [&](const char* key) {
        if (!status.is_object() || !status.contains("measured") || !status["measured"].contains(key)) return nan;
        const auto& m = status["measured"][key];
        return m.contains("setpoint") && m["setpoint"].is_number() ? m["setpoint"].get<double>() : nan;
    };
    auto either = [](double a, double b) { return std::isnan(a) ? b : a; };
    points_.push_back({now_s, utc_ms, value("datalogger/ee181_1.air_temp_c"), value("chamber/air_temp_pv_c"),
                       either(value("chamber/air_temp_remote_setpoint_c"), sent("chamber_air_temp_c")),
                       value("datalogger/ee181_1.air_rh_pct"), value("chamber/air_rh_pv_pct"),
                       either(value("chamber/air_rh_remote_setpoint_pct"), sent("chamber_air_rh_pct")),
                       value("windsonic/air_speed_m_s"),
                       status.is_object() && status.contains("stage") && status["stage"].is_string() ? status["stage"].get<std::string>() : ""});
    while (!points_.empty() && now_s - points_.front().t_s > keep_s_) points_.pop_front();
}

void ChamberHistory::seed(std::vector<Point> points, double now_s, std::int64_t now_utc_ms,
                          std::map<std::string, std::int64_t> campaign_starts_utc_ms) {
    campaign_starts_ = std::move(campaign_starts_utc_ms);
    if (!campaign_.empty())
        if (const auto it = campaign_starts_.find(campaign_); it != campaign_starts_.end()) campaign_start_utc_ms_ = it->second;
    const std::int64_t first_live_ms = points_.empty() ? now_utc_ms + 1 : points_.front().utc_ms;
    std::deque<Point> older;
    for (auto& p : points) {
        if (p.utc_ms >= first_live_ms || now_utc_ms - p.utc_ms > static_cast<std::int64_t>(keep_s_ * 1000)) continue;
        p.t_s = now_s - static_cast<double>(now_utc_ms - p.utc_ms) / 1000.0;  // this console's steady clock
        older.push_back(std::move(p));
    }
    if (!older.empty()) seeded_until_utc_ms_ = older.back().utc_ms;
    for (auto& p : points_) older.push_back(std::move(p));
    points_ = std::move(older);
}

std::size_t ChamberHistory::first_of(const std::string& span) const {
    std::int64_t since_ms = 0;
    if (span == "trial" && trial_start_utc_ms_ > 0) since_ms = trial_start_utc_ms_;
    else if (span == "campaign" && campaign_start_utc_ms_ > 0) since_ms = campaign_start_utc_ms_;
    else if (!points_.empty()) {
        const double since_s = points_.back().t_s - 3600.0;
        std::size_t i = 0;
        while (i < points_.size() && points_[i].t_s < since_s) ++i;
        return i;
    }
    std::size_t i = 0;
    while (i < points_.size() && points_[i].utc_ms < since_ms) ++i;
    return i;
}

nlohmann::json ChamberHistory::points_json(const std::string& span, std::size_t max_points) const {
    nlohmann::json a = nlohmann::json::array();
    const std::size_t first = first_of(span);
    const std::size_t n = points_.size() - first;
    if (n == 0 || max_points == 0) return a;
    const std::size_t stride = (n + max_points - 1) / max_points;
    auto number = [](double v) { return std::isnan(v) ? nlohmann::json(nullptr) : nlohmann::json(v); };
    for (std::size_t k = 0; k < n; k += stride) {
        // The newest point always: the chart ends at now.
        const std::size_t i = first + (k + stride >= n ? n - 1 : k);
        const auto& p = points_[i];
        a.push_back({{"t_s", p.t_s},
                     {"utc_ms", p.utc_ms},
                     {"air_temp_c", number(p.air_temp_c)},
                     {"air_temp_pv_c", number(p.air_temp_pv_c)},
                     {"air_temp_setpoint_c", number(p.air_temp_setpoint_c)},
                     {"air_rh_pct", number(p.air_rh_pct)},
                     {"air_rh_pv_pct", number(p.air_rh_pv_pct)},
                     {"air_rh_setpoint_pct", number(p.air_rh_setpoint_pct)},
                     {"air_speed_m_s", number(p.air_speed_m_s)},
                     {"stage", p.stage}});
        if (i == first + n - 1) break;
    }
    return a;
}

nlohmann::json ChamberHistory::to_json(const std::string& span, std::size_t max_points) const {
    const std::string s = span == "trial" || span == "campaign" ? span : "1h";
    const std::size_t first = first_of(s);
    return {{"span", s},
            {"step_s", step_s_},
            {"keep_s", keep_s_},
            {"covers_from_utc_ms", first < points_.size() ? nlohmann::json(points_[first].utc_ms) : nlohmann::json(nullptr)},
            {"from_database_until_utc_ms", seeded_until_utc_ms_ > 0 ? nlohmann::json(seeded_until_utc_ms_) : nlohmann::json(nullptr)},
            {"trial_start_utc_ms", trial_start_utc_ms_ > 0 ? nlohmann::json(trial_start_utc_ms_) : nlohmann::json(nullptr)},
            {"campaign", campaign_.empty() ? nlohmann::json(nullptr) : nlohmann::json(campaign_)},
            {"campaign_start_utc_ms", campaign_start_utc_ms_ > 0 ? nlohmann::json(campaign_start_utc_ms_) : nlohmann::json(nullptr)},
            {"points", points_json(s, max_points)}};
}

nlohmann::json twin_zone_fluxes(const nlohmann::json& live, bool wet) {
    // The mean of the good readings of every channel whose key matches (device/prefix*suffix).
    auto mean = [&](const std::string& device_prefix, const std::string& suffix) -> std::optional<double> {
        double sum = 0;
        int n = 0;
        for (const auto& [key, v] : live.items())
            if (key.rfind(device_prefix, 0) == 0 && key.size() >= suffix.size() &&
                key.compare(key.size() - suffix.size(), suffix.size(), suffix) == 0 && v.value("quality", "") == "good" &&
                v.contains("value") && v["value"].is_number()) {
                sum += v["value"].get<double>();
                ++n;
            }
        if (n == 0) return std::nullopt;
        return sum / n;
    };
    physics::twin::TrialConditions c;
    const auto air = mean("datalogger/ee181_", ".air_temp_c"), rh = mean("datalogger/ee181_", ".air_rh_pct");
    if (!air || !rh) return nullptr;
    c.air_temp_c = *air;
    c.air_rh_pct = *rh;
    c.wall_temp_c = mean("datalogger/wall_tc_", ".wall_temp_c");
    c.air_speed_m_s = mean("windsonic/", "air_speed_m_s");
    c.wettedness = wet ? 1.0 : 0.0;
    for (const auto& z : analysis::andi35_zone_map().zones) {
        const auto skin = mean(fmt::format("manikin/z{:02d}.", z.zone), "skin_temp_c");
        if (!skin) return nullptr;
        c.zones.push_back({z.zone, z.segment, z.region, z.area_m2, *skin});
    }
    static const auto baseline = twin_store::load_twin_version("baseline");
    nlohmann::json out = nlohmann::json::object();
    for (const auto& f : physics::twin::predict(baseline, c)) out[std::to_string(f.zone)] = f.q_total_w_m2;
    return out;
}

std::string prometheus_text(const nlohmann::json& status, const nlohmann::json& live) {
    std::string out;
    auto family = [&](const char* name, const char* type, const char* help) {
        out += fmt::format("# HELP {} {}\n# TYPE {} {}\n", name, help, name, type);
    };
    const auto& devices = status.contains("devices") ? status["devices"] : nlohmann::json::array();
    family("manikind_device_connected", "gauge", "1 when the device is connected.");
    for (const auto& d : devices)
        out += fmt::format("manikind_device_connected{{device=\"{}\"}} {}\n", label(d.value("name", "")),
                           d.value("connected", false) ? 1 : 0);
    family("manikind_device_stale", "gauge", "1 when the device's values are stale.");
    for (const auto& d : devices)
        out += fmt::format("manikind_device_stale{{device=\"{}\"}} {}\n", label(d.value("name", "")), d.value("stale", false) ? 1 : 0);
    family("manikind_device_severity", "gauge", "EPICS alarm severity: 0 NO_ALARM, 1 MINOR, 2 MAJOR, 3 INVALID.");
    for (const auto& d : devices)
        out += fmt::format("manikind_device_severity{{device=\"{}\"}} {}\n", label(d.value("name", "")), d.value("severity_level", 0));
    for (const char* c : {"samples", "frames", "checksum_errors", "malformed", "timeouts", "exceptions", "reconnects",
                          "comm_errors", "device_faults"}) {
        const std::string name = fmt::format("manikind_device_{}_total", c);
        family(name.c_str(), "counter", fmt::format("The device driver's {} counter.", c).c_str());
        for (const auto& d : devices)
            out += fmt::format("{}{{device=\"{}\"}} {}\n", name, label(d.value("name", "")), counter(d, c));
    }
    family("manikind_live_value", "gauge", "The latest reading of each channel, in the unit its name ends with.");
    for (const auto& [key, v] : live.items()) {
        const auto slash = key.find('/');
        const std::string device = key.substr(0, slash), channel = slash == std::string::npos ? key : key.substr(slash + 1);
        const double value = v.contains("value") && v["value"].is_number() ? v["value"].get<double>() : std::nan("");
        out += fmt::format("manikind_live_value{{device=\"{}\",channel=\"{}\",quality=\"{}\"}} {}\n", label(device), label(channel),
                           label(v.value("quality", "")), number(value));
    }
    family("manikind_live_age_seconds", "gauge", "Seconds since each channel's latest reading.");
    for (const auto& [key, v] : live.items()) {
        const auto slash = key.find('/');
        const std::string device = key.substr(0, slash), channel = slash == std::string::npos ? key : key.substr(slash + 1);
        out += fmt::format("manikind_live_age_seconds{{device=\"{}\",channel=\"{}\"}} {}\n", label(device), label(channel),
                           number(v.value("age_s", std::nan(""))));
    }
    if (status.contains("recorder")) {
        const auto& r = status["recorder"];
        family("manikind_recorder_accepted_rows_total", "counter", "Readings handed to the recorder.");
        out += fmt::format("manikind_recorder_accepted_rows_total {}\n", counter(r, "accepted"));
        family("manikind_recorder_committed_rows_total", "counter", "Readings committed to the database.");
        out += fmt::format("manikind_recorder_committed_rows_total {}\n", counter(r, "committed"));
        family("manikind_recorder_dropped_rows_total", "counter",
               "Readings not stored, whatever the cause (queue full, re-sent duplicates, lost after retries).");
        out += fmt::format("manikind_recorder_dropped_rows_total {}\n", counter(r, "dropped"));
        family("manikind_recorder_duplicate_rows_total", "counter", "Re-sent readings skipped: already stored.");
        out += fmt::format("manikind_recorder_duplicate_rows_total {}\n", counter(r, "duplicates"));
        family("manikind_recorder_queue_full_rows_total", "counter", "Readings dropped because the recorder queue was full.");
        out += fmt::format("manikind_recorder_queue_full_rows_total {}\n", counter(r, "dropped_queue_full"));
        family("manikind_recorder_queue_rows", "gauge", "Readings accepted but not yet committed.");
        out += fmt::format("manikind_recorder_queue_rows {}\n", counter(r, "queue_rows"));
    }
    family("manikind_trial_stage", "gauge", "1 for the trial stage the daemon is in.");
    const std::string stage = status.value("stage", "idle");
    for (const char* s : {"idle", "configuring", "chamber_settling", "manikin_starting", "acquiring", "stopping", "computing"})
        out += fmt::format("manikind_trial_stage{{stage=\"{}\"}} {}\n", s, stage == s ? 1 : 0);
    family("manikind_campaign_trials_done", "gauge", "Trials of the running campaign that have ended.");
    out += fmt::format("manikind_campaign_trials_done {}\n", status.value("trials_done", 0));
    family("manikind_campaign_trials_total", "gauge", "Trials in the running campaign.");
    out += fmt::format("manikind_campaign_trials_total {}\n", status.value("trials_total", 0));
    family("manikind_paused", "gauge", "1 while the campaign is paused.");
    out += fmt::format("manikind_paused {}\n", status.value("paused", false) ? 1 : 0);
    family("manikind_safety_tripped", "gauge", "1 once a safety limit has stopped heating.");
    out += fmt::format("manikind_safety_tripped {}\n", status.value("safety_tripped", false) ? 1 : 0);
    return out;
}

}  // namespace manikind::console
