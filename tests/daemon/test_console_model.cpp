// What the console and /metrics compute from the daemon's status (console_model): EPICS
// severities by the documented rules, the Prometheus exposition's escaping, the chamber history.
#include <catch2/catch.hpp>

#include <fmt/format.h>

#include "daemon/console_model.hpp"

using manikind::console::ChamberHistory;
using manikind::console::DeviceSeverity;

namespace {
nlohmann::json device(const std::string& name, bool connected, bool stale, unsigned timeouts) {
    return {{"name", name}, {"connected", connected}, {"stale", stale}, {"timeouts", timeouts}, {"checksum_errors", 0u},
            {"exceptions", 0u}, {"malformed", 0u}, {"device_faults", 0u}};
}
}  // namespace

TEST_CASE("device severity: INVALID when disconnected, MAJOR when stale, MINOR for 60 s after an error count rises",
          "[daemon][console]") {
    DeviceSeverity sev(60.0);
    nlohmann::json devices = {device("chamber", true, false, 0), device("windsonic", false, false, 0),
                              device("csat3b", true, true, 0)};
    sev.annotate(devices, 0.0);
    CHECK(devices[0]["severity"] == "NO_ALARM");
    CHECK(devices[1]["severity"] == "INVALID");
    CHECK(devices[2]["severity"] == "MAJOR");
    devices[0]["timeouts"] = 2u;  // the chamber timed out twice
    sev.annotate(devices, 10.0);
    CHECK(devices[0]["severity"] == "MINOR");
    sev.annotate(devices, 70.0);  // no new errors for 60 s
    CHECK(devices[0]["severity"] == "MINOR");
    sev.annotate(devices, 70.5);
    CHECK(devices[0]["severity"] == "NO_ALARM");
    CHECK(devices[0]["severity_level"] == 0);
}

TEST_CASE("Prometheus text: one TYPE per family, label values escaped, NaN spelt as the format says", "[daemon][console]") {
    nlohmann::json status = {{"devices", nlohmann::json::array({device("odd\"name\\", true, false, 3)})},
                             {"stage", "acquiring"},
                             {"recorder", {{"accepted", 10u}, {"committed", 7u}, {"dropped", 4u}, {"duplicates", 3u}, {"queue_rows", 2u}}}};
    nlohmann::json live = {{"manikin/z01.skin_temp_c", {{"value", 34.5}, {"quality", "good"}, {"age_s", 2.0}}},
                           {"windsonic/air_speed_m_s", {{"value", nullptr}, {"quality", "comm_error"}, {"age_s", 9.0}}}};
    const std::string text = manikind::console::prometheus_text(status, live);
    CHECK(text.find("manikind_device_timeouts_total{device=\"odd\\\"name\\\\\"} 3\n") != std::string::npos);
    CHECK(text.find("manikind_live_value{device=\"manikin\",channel=\"z01.skin_temp_c\",quality=\"good\"} 34.5\n") !=
          std::string::npos);
    CHECK(text.find("channel=\"air_speed_m_s\",quality=\"comm_error\"} NaN\n") != std::string::npos);
    CHECK(text.find("manikind_trial_stage{stage=\"acquiring\"} 1\n") != std::string::npos);
    CHECK(text.find("manikind_trial_stage{stage=\"idle\"} 0\n") != std::string::npos);
    CHECK(text.find("manikind_recorder_queue_rows 2\n") != std::string::npos);
    CHECK(text.find("manikind_recorder_duplicate_rows_total 3\n") != std::string::npos);
    CHECK(text.find("manikind_recorder_dropped_rows_total 4\n") != std::string::npos);
    std::size_t types = 0;
    for (auto p = text.find("# TYPE manikind_live_value "); p != std::string::npos; p = text.find("# TYPE manikind_live_value ", p + 1))
        ++types;
    CHECK(types == 1);
}

TEST_CASE("chamber history keeps one point per step over the last hour", "[daemon][console]") {
    ChamberHistory h(3600.0, 5.0);
    for (int t = 0; t <= 7200; ++t)
        h.add(t, {{"datalogger/ee181_1.air_temp_c", {{"value", 20.0 + t * 1e-3}}}});
    const auto points = h.to_json();
    REQUIRE(points.size() == 721);  // 3600 s / 5 s + the newest
    CHECK(points.front()["t_s"] == 3600.0);
    CHECK(points.back()["t_s"] == 7200.0);
    CHECK(points.back()["air_temp_c"] == Approx(27.2));
    CHECK(points.back()["air_rh_pct"].is_null());  // a channel not seen is null, not zero
}

TEST_CASE("the twin's zone fluxes at live conditions: every zone once inputs are there, null while one is missing",
          "[daemon][console]") {
    nlohmann::json live = {{"datalogger/ee181_1.air_temp_c", {{"value", 30.0}, {"quality", "good"}}},
                           {"datalogger/ee181_1.air_rh_pct", {{"value", 40.0}, {"quality", "good"}}},
                           {"windsonic/air_speed_m_s", {{"value", 0.1}, {"quality", "good"}}}};
    CHECK(manikind::console::twin_zone_fluxes(live, false).is_null());  // no skin temperatures yet
    for (int z = 1; z <= 35; ++z)
        live[fmt::format("manikin/z{:02d}.skin_temp_c", z)] = {{"value", 34.0}, {"quality", "good"}};
    const auto dry = manikind::console::twin_zone_fluxes(live, false);
    const auto wet = manikind::console::twin_zone_fluxes(live, true);
    REQUIRE(dry.size() == 35);
    // Skin 4 °C above the air loses heat by convection and radiation; a wet skin loses more
    // (evaporation at 40 % RH).
    for (const auto& [zone, q] : dry.items()) {
        CHECK(q.get<double>() > 0.0);
        CHECK(wet[zone].get<double>() > q.get<double>());
    }
}
