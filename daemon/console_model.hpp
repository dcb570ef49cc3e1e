#pragma once
// What the operator console and /metrics show, computed from the daemon's status and live JSON
// (no I/O, no clock: time is passed in, so every rule here is unit-tested).
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <string>

#include <nlohmann/json.hpp>

namespace manikind::console {

// EPICS alarm severities, as labs know them from their IOCs.
enum class Severity { no_alarm = 0, minor = 1, major = 2, invalid = 3 };
const char* to_string(Severity s);

// A device's severity: INVALID when it is not connected (its values cannot be trusted at all),
// MAJOR when connected but its values are stale, MINOR when an error counter (checksum, timeout,
// exception, malformed, device fault) rose within the last `minor_hold_s`, else NO_ALARM.
class DeviceSeverity {
public:
    explicit DeviceSeverity(double minor_hold_s = 60.0) : minor_hold_s_(minor_hold_s) {}
    // Adds "severity" (and "severity_reason") to each entry of status["devices"].
    void annotate(nlohmann::json& devices, double now_s);

private:
    double minor_hold_s_;
    std::map<std::string, std::uint64_t> last_errors_;
    std::map<std::string, double> last_rise_s_;
};

// The chamber's history for the page's time-axis charts: air temperature and RH (EE181 probe 1,
// the enclosure's reading, and the controller's own PV) against their setpoints, and air speed,
// one point per `step_s`, kept for `keep_s` (24 h: 17,280 points of 80 bytes). The setpoint is
// the controller's remote-setpoint register where it is read, else the one the daemon last sent.
// Spans (issue 35): the last hour, the running (or last) trial, the running (or last) campaign,
// each since the daemon started at the earliest (said in `covers_from_utc_ms`).
class ChamberHistory {
public:
    explicit ChamberHistory(double keep_s = 24 * 3600.0, double step_s = 5.0) : keep_s_(keep_s), step_s_(step_s) {}
    // now_s: a steady clock; utc_ms: the wall clock; status: the daemon's (trial id, campaign,
    // stage, measured setpoints); live: its channels.
    void add(double now_s, std::int64_t utc_ms, const nlohmann::json& live, const nlohmann::json& status = nullptr);
    // span: "1h", "trial", "campaign" (else UserError-free: unknown spans read as "1h"). At most
    // `max_points` points, thinned evenly (the newest always kept).
    nlohmann::json to_json(const std::string& span = "1h", std::size_t max_points = 720) const;
    // The points alone (the span's), as the page's older /api/history gave them.
    nlohmann::json points_json(const std::string& span = "1h", std::size_t max_points = 720) const;

    struct Point {
        double t_s;
        std::int64_t utc_ms;
        double air_temp_c, air_temp_pv_c, air_temp_setpoint_c, air_rh_pct, air_rh_pv_pct, air_rh_setpoint_pct, air_speed_m_s;
        std::string stage;
    };
    // The history before this console started, read from the database (the idle log and the
    // trials' samples: docs/daemon.md, "Console"), in time order with t_s unset: placed before
    // the points already held (older than the first of them), on this console's clock
    // (now_s, now_utc_ms). `campaign_starts_utc_ms`: when each campaign was created, so a
    // campaign span starts there rather than when this console first saw it.
    void seed(std::vector<Point> points, double now_s, std::int64_t now_utc_ms,
              std::map<std::string, std::int64_t> campaign_starts_utc_ms);

private:
    std::size_t first_of(const std::string& span) const;
    double keep_s_, step_s_;
    double last_s_ = -1e300;
    std::deque<Point> points_;
    // Where the spans begin: the wall time the running (or last) trial and campaign were first seen.
    std::int64_t trial_id_ = 0, trial_start_utc_ms_ = 0, campaign_start_utc_ms_ = 0;
    std::string campaign_;
    std::map<std::string, std::int64_t> campaign_starts_;  // from the database
    std::int64_t seeded_until_utc_ms_ = 0;                  // 0: nothing from the database (yet)
};

// The baseline twin's heat flux for every zone at the live conditions (EE181 air temperature and
// RH, wall thermocouples, WindSonic air speed, each zone's live skin temperature; wet or dry as
// the running case): {"1": W/m², ...}, or null while an input is missing. The console colours
// zones by measured minus this.
nlohmann::json twin_zone_fluxes(const nlohmann::json& live, bool wet);

// Prometheus text exposition format 0.0.4: device counters and severities, live values with
// their age, recorder rows, the trial stage and campaign progress.
std::string prometheus_text(const nlohmann::json& status, const nlohmann::json& live);

}  // namespace manikind::console
