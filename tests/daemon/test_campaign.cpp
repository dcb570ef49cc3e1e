// Whole campaigns through the daemon on the simulated lab: the state machine, the recorder, the
// results; a device dropping out for 60 s mid-trial; the daemon's own safety stops.
#include <catch2/catch.hpp>

#include <map>

#include "daemon/core/database_export.hpp"
#include "daemon_fixture.hpp"

using manikind::test::DaemonFixture;
using manikind::test::quick_plan;

TEST_CASE("a campaign runs through every stage, records, and stores results", "[daemon]") {
    DaemonFixture f;
    REQUIRE(f.daemon().start_campaign(quick_plan("quick")).empty());
    REQUIRE(f.daemon().start_campaign(quick_plan("second")).empty());  // queued behind the first
    CHECK(f.daemon().status_json()["queued_campaigns"] == nlohmann::json::array({"second"}));
    CHECK_FALSE(f.daemon().start_campaign(quick_plan("second")).empty());  // names are unique
    f.daemon().run_virtual();
    CHECK(f.daemon().db().trials(*f.daemon().db().find_campaign("second")).at(0).state == "done");
    auto& db = f.daemon().db();
    const auto id = db.find_campaign("quick");
    REQUIRE(id);
    const auto trials = db.trials(*id);
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "done");
    CHECK(trials[0].steady_from_mono_ns.has_value());
    CHECK(trials[0].quality_flags == 0);
    std::vector<std::string> stages;
    for (const auto& e : db.events(trials[0].id))
        if (e.kind == "stage") stages.push_back(e.message);
    CHECK(stages == std::vector<std::string>{"configuring", "chamber_settling", "manikin_starting", "acquiring", "stopping"});
    const auto campaign = manikind::campaign_from_database(db, "quick");
    REQUIRE(campaign.trials.size() == 1);
    CHECK(campaign.trials[0].data.rows() >= 35 * 60 / 5);
    // Enclosure air at case 5 of Table S3: 35.3 °C.
    CHECK(campaign.trials[0].data.air_temp_c.back() == Approx(35.3).margin(0.3));
    const auto results = f.daemon().results_json("quick");
    INFO(results["excluded_trials"].dump() << results["unanalysed_cases"].dump().substr(0, 300));
    REQUIRE(results["cases"].size() == 1);
    CHECK(std::isfinite(results["cases"][0]["whole_body"]["q_w_m2"].get<double>()));
    CHECK(db.integrity_check() == "ok");
    std::map<std::string, std::string> units;
    for (const auto& ch : db.channels()) units[ch.device_name + "/" + ch.name] = ch.unit;
    CHECK(units["manikin/z01.skin_temp_c"] == "°C");
    CHECK(units["manikin/z01.heat_flux_w_m2"] == "W/m²");
    CHECK(units["manikin/z01.sweat_rate_g_m2_h"] == "g/(m² h)");
    CHECK(units["datalogger/ee181_1.air_rh_pct"] == "%");
    CHECK(units["windsonic/air_speed_m_s"] == "m/s");
    CHECK(units["csat3b/sonic_temp_c"] == "°C");
}

TEST_CASE("a device dropping out for 60 s mid-trial: the others go on, the gap is recorded, the trial flagged",
          "[daemon]") {
    DaemonFixture f([](manikind::config::Config& c) { c.simulation.faults = {"windsonic:silent@3300-3360"}; });
    REQUIRE(f.daemon().start_campaign(quick_plan("dropout", 40)).empty());
    f.daemon().run_virtual();
    auto& db = f.daemon().db();
    const auto trials = db.trials(*db.find_campaign("dropout"));
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "done");
    CHECK((trials[0].quality_flags & manikind::flag_device_gap) != 0);
    std::vector<std::string> gaps;
    for (const auto& e : db.events(trials[0].id))
        if (e.kind == "gap") gaps.push_back(e.message);
    REQUIRE(gaps.size() == 2);
    CHECK(gaps[0].find("windsonic lost") == 0);
    CHECK(gaps[1].find("windsonic back after") == 0);
    // The manikin kept reporting through the gap.
    std::int64_t manikin_channel = 0, speed_channel = 0;
    for (const auto& ch : db.channels()) {
        if (ch.device_name == "manikin" && ch.name == "z01.skin_temp_c") manikin_channel = ch.id;
        if (ch.device_name == "windsonic" && ch.name == "air_speed_m_s") speed_channel = ch.id;
    }
    int manikin_in_gap = 0, good_speed_in_gap = 0;
    for (const auto& s : db.samples(trials[0].id, manikin_channel))
        if (s.mono_ns > 3310'000'000'000LL && s.mono_ns < 3350'000'000'000LL) ++manikin_in_gap;
    for (const auto& s : db.samples(trials[0].id, speed_channel))
        if (s.mono_ns > 3310'000'000'000LL && s.mono_ns < 3350'000'000'000LL && s.quality == 0) ++good_speed_in_gap;
    CHECK(manikin_in_gap >= 7);
    CHECK(good_speed_in_gap == 0);
}

TEST_CASE("the daemon stops heating itself when the manikin goes silent (watchdog)", "[daemon][safety]") {
    DaemonFixture f([](manikind::config::Config& c) { c.simulation.faults = {"manikin:silent@3000"}; });
    REQUIRE(f.daemon().start_campaign(quick_plan("watchdog")).empty());
    f.daemon().run_virtual();
    auto& db = f.daemon().db();
    const auto trials = db.trials(*db.find_campaign("watchdog"));
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "failed");
    CHECK(trials[0].reason.find("watchdog: manikin silent") != std::string::npos);
    CHECK((trials[0].quality_flags & manikind::flag_safety_stop) != 0);
    CHECK_FALSE(f.daemon().acquisition().manikin().running_command());
    bool recorded = false;
    for (const auto& e : db.events(std::nullopt)) recorded = recorded || (e.kind == "safety" && e.severity == "error");
    CHECK(recorded);
}

TEST_CASE("the daemon stops heating when a zone exceeds the skin temperature limit", "[daemon][safety]") {
    DaemonFixture f([](manikind::config::Config& c) { c.safety.max_skin_temp_c = 34.0; c.safety.min_skin_temp_c = 20.0; });
    auto plan = quick_plan("overheat");
    plan.cases[0].skin_setpoint_c = 33.9;  // inside the limit; the PI loop's overshoot is not
    plan.cases[0].chamber_temp_c = 44.0;   // hot chamber: the zones are pushed above the setpoint
    REQUIRE(f.daemon().start_campaign(plan).empty());
    f.daemon().run_virtual();
    auto& db = f.daemon().db();
    const auto trials = db.trials(*db.find_campaign("overheat"));
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "failed");
    CHECK(trials[0].reason.find("safety.max_skin_temp_c") != std::string::npos);
}

TEST_CASE("pause holds the stage clock, abort ends the campaign", "[daemon]") {
    DaemonFixture f;
    REQUIRE(f.daemon().start_campaign(quick_plan("pausing")).empty());
    for (int i = 0; i < 100; ++i) f.daemon().step_virtual(1.0);
    REQUIRE(f.daemon().pause().empty());
    const double held = f.daemon().status_json()["trial"]["stage_elapsed_s"].get<double>();
    for (int i = 0; i < 100; ++i) f.daemon().step_virtual(1.0);
    CHECK(f.daemon().status_json()["trial"]["stage_elapsed_s"].get<double>() == Approx(held));
    REQUIRE(f.daemon().resume().empty());
    REQUIRE(f.daemon().abort("operator").empty());
    const auto trials = f.daemon().db().trials(*f.daemon().db().find_campaign("pausing"));
    CHECK(trials[0].state == "aborted");
    CHECK(f.daemon().status_json()["campaign"].is_null());
}
