#pragma once
// What the operator console and /metrics show, computed from the daemon's status and live JSON
// (no I/O, no clock: time is passed in, so every rule here is unit-tested).
#include <deque>
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

// The chamber's last hour for the page's charts: air temperature and RH (EE181 probe 1 and the
// controller's PV) against their setpoints, and air speed, one point per `step_s`.
class ChamberHistory {
public:
    explicit ChamberHistory(double keep_s = 3600.0, double step_s = 5.0) : keep_s_(keep_s), step_s_(step_s) {}
    void add(double now_s, const nlohmann::json& live);
    nlohmann::json to_json() const;

private:
    double keep_s_, step_s_;
    double last_s_ = -1e300;
    std::deque<nlohmann::json> points_;
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
