// What the console and /metrics compute from the daemon's status (console_model): EPICS
// severities by the documented rules, the Prometheus exposition's escaping, the chamber history.
#include <catch2/catch.hpp>

#include <fmt/format.h>

#include <cmath>
#include <vector>

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
        h.add(t, 1'780'000'000'000 + t * 1000LL, {{"datalogger/ee181_1.air_temp_c", {{"value", 20.0 + t * 1e-3}}}});
    const auto points = h.points_json("1h", 1000);
    REQUIRE(points.size() == 721);  // 3600 s / 5 s + the newest
    CHECK(points.front()["t_s"] == 3600.0);
    CHECK(points.back()["t_s"] == 7200.0);
    CHECK(points.back()["utc_ms"] == 1'780'000'000'000 + 7'200'000LL);
    CHECK(points.back()["air_temp_c"] == Approx(27.2));
    CHECK(points.back()["air_rh_pct"].is_null());  // a channel not seen is null, not zero
    // Thinned to the page's 720 points at most, evenly, the newest kept.
    const auto thin = h.points_json("1h", 100);
    CHECK(thin.size() <= 100);
    CHECK(thin.size() >= 90);
    CHECK(thin.back()["t_s"] == 7200.0);
}

TEST_CASE("chamber history: spans of the trial and the campaign, the setpoint the daemon sent where the register is not read",
          "[daemon][console]") {
    ChamberHistory h(24 * 3600.0, 5.0);
    const std::int64_t t0_ms = 1'780'000'000'000;
    auto status = [](nlohmann::json trial_id, nlohmann::json campaign, double setpoint) {
        return nlohmann::json{{"campaign", campaign},
                              {"stage", trial_id.is_null() ? "idle" : "acquiring"},
                              {"trial", trial_id.is_null() ? nlohmann::json(nullptr) : nlohmann::json{{"id", trial_id}}},
                              {"measured", {{"chamber_air_temp_c", {{"value", 30.0}, {"setpoint", setpoint}}}}}};
    };
    const nlohmann::json live = {{"datalogger/ee181_1.air_temp_c", {{"value", 30.0}}}};
    for (int t = 0; t < 600; t += 5) h.add(t, t0_ms + t * 1000LL, live, status(nullptr, nullptr, 25.0));           // idle
    for (int t = 600; t < 3000; t += 5) h.add(t, t0_ms + t * 1000LL, live, status(7, "c", 35.0));                 // trial 7
    for (int t = 3000; t <= 4000; t += 5) h.add(t, t0_ms + t * 1000LL, live, status(8, "c", 40.0));               // trial 8
    const auto trial = h.to_json("trial");
    CHECK(trial["span"] == "trial");
    CHECK(trial["trial_start_utc_ms"] == t0_ms + 3'000'000);
    CHECK(trial["points"].front()["t_s"] == 3000.0);
    CHECK(trial["points"].front()["air_temp_setpoint_c"] == 40.0);  // the daemon's, no register in live
    const auto campaign = h.to_json("campaign");
    CHECK(campaign["campaign"] == "c");
    CHECK(campaign["points"].front()["t_s"] == 600.0);
    CHECK(campaign["points"].front()["stage"] == "acquiring");
    CHECK(h.to_json("nonsense")["span"] == "1h");
    // A register read back wins over what the daemon sent.
    nlohmann::json with_register = live;
    with_register["chamber/air_temp_remote_setpoint_c"] = {{"value", 39.5}};
    h.add(4010, t0_ms + 4'010'000, with_register, status(8, "c", 40.0));
    CHECK(h.points_json("trial").back()["air_temp_setpoint_c"] == 39.5);
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

TEST_CASE("chamber history: points read from the database go before the live ones, on the console's clock", "[daemon][console]") {
    ChamberHistory h(24 * 3600.0, 5.0);
    const std::int64_t now_ms = 1'780'000'000'000;
    h.add(1000.0, now_ms, {{"datalogger/ee181_1.air_temp_c", {{"value", 30.0}}}});
    std::vector<ChamberHistory::Point> older;
    const double nan = std::nan("");
    for (int i = 0; i < 10; ++i)  // the ten minutes before this console started, every minute
        older.push_back({0.0, now_ms - (600 - 60 * i) * 1000LL, 29.0 + 0.1 * i, nan, 35.0, 40.0, nan, 30.0, nan, "trial"});
    older.push_back({0.0, now_ms + 5000, 99.0, nan, nan, nan, nan, nan, nan, "idle"});   // not older than the live: dropped
    older.push_back({0.0, now_ms - 25 * 3600 * 1000LL, 1.0, nan, nan, nan, nan, nan, nan, "idle"});  // beyond the day kept
    h.seed(older, 1000.0, now_ms, {{"c", now_ms - 3'600'000}});
    const auto all = h.points_json("1h", 1000);
    REQUIRE(all.size() == 11);
    CHECK(all.front()["utc_ms"] == now_ms - 600'000);
    CHECK(all.front()["t_s"] == Approx(400.0));  // 600 s before now on the steady clock
    CHECK(all.front()["air_temp_setpoint_c"] == 35.0);
    CHECK(all.back()["air_temp_c"] == 30.0);  // the live point stays last
    CHECK(h.to_json("1h")["from_database_until_utc_ms"] == now_ms - 60'000);
    // A campaign the database knows starts its span where it was created.
    h.add(1005.0, now_ms + 5000, {}, {{"campaign", "c"}});
    CHECK(h.to_json("campaign")["campaign_start_utc_ms"] == now_ms - 3'600'000);
}
