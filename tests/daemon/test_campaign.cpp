// Whole campaigns through the daemon on the simulated lab: the state machine, the recorder, the
// results; a device dropping out for 60 s mid-trial; the daemon's own safety stops.
#include <catch2/catch.hpp>

#include <cmath>
#include <map>

#include "daemon/campaign_plan.hpp"
#include "daemon/control_api.hpp"
#include "store/database_export.hpp"
#include "daemon/setup_record.hpp"
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
    // The trial names the set-up it ran with: chamber, manikin, calibration and configuration.
    REQUIRE(trials[0].setup_id.has_value());
    const auto setup = db.setup(*trials[0].setup_id);
    REQUIRE(setup);
    CHECK(setup->setup.chamber == f.daemon().config().chamber);
    CHECK_THAT(setup->setup.manikin, Catch::Contains("35-zone"));
    CHECK(setup->setup.config_toml == manikind::redact_secrets(f.daemon().config().source_text));
    CHECK_THAT(setup->setup.config_toml, Catch::Contains("[steady_state]"));
    CHECK_THAT(setup->setup.calibration_json, Catch::Contains("\"air_rh_pct\"") && Catch::Contains("ee181"));
    // Both campaigns of this run share it.
    CHECK(db.trials(*db.find_campaign("second")).at(0).setup_id == trials[0].setup_id);
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
    // The final results carry the console's parity point: the baseline twin at the case's
    // recorded conditions against the measured whole-body flux.
    CHECK(results["interim"] == false);
    REQUIRE(results["twin_parity"].size() == 1);
    const auto& parity = results["twin_parity"][0];
    CHECK(parity["measured_w_m2"].get<double>() == Approx(results["cases"][0]["whole_body"]["q_w_m2"].get<double>()));
    INFO("twin " << parity["twin_w_m2"] << " measured " << parity["measured_w_m2"]);
    // The simulated world has humidity-driven buoyancy (gamma 146) that the baseline twin lacks: at
    // this case (air = skin = 35 °C, wet) the twin sees no temperature-driven convection, so it
    // must predict less heat loss than the world gives (the paper's point, which reconcile finds).
    CHECK(parity["twin_w_m2"].get<double>() > 0.0);
    CHECK(parity["twin_w_m2"].get<double>() < parity["measured_w_m2"].get<double>() - parity["U_w_m2"].get<double>());
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

TEST_CASE("a campaign recorded with [recorder] journal = rollback: the file stays in rollback mode, and nothing is lost",
          "[daemon][journal]") {
    DaemonFixture f([](manikind::config::Config& c) { c.recorder_journal = "rollback"; });
    CHECK(f.daemon().status_json()["recorder"]["journal"] == "truncate");
    REQUIRE(f.daemon().start_campaign(quick_plan("rollback")).empty());
    f.daemon().run_virtual();
    auto& db = f.daemon().db();
    CHECK(db.journal_mode() != "wal");  // a reader sees rollback mode ("delete": TRUNCATE is the writer's own)
    CHECK(f.daemon().status_json()["recorder"]["journal"] == "truncate");
    const auto trials = db.trials(*db.find_campaign("rollback"));
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "done");
    // Every reading the recorder accepted is stored: the trial-end export and the results read
    // between its commits, and each commit waited for them rather than failing.
    const auto status = f.daemon().status_json()["recorder"];
    CHECK(status["committed"] == status["accepted"]);
    CHECK(status["lost_after_retries"] == 0);
    const auto campaign = manikind::campaign_from_database(db, "rollback");
    REQUIRE(campaign.trials.size() == 1);
    CHECK(campaign.trials[0].data.rows() >= 35 * 60 / 5);
    CHECK(std::isfinite(f.daemon().results_json("rollback")["cases"][0]["whole_body"]["q_w_m2"].get<double>()));
    CHECK(db.integrity_check() == "ok");
    CHECK_FALSE(std::filesystem::exists(f.daemon().config().database.string() + "-wal"));
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

TEST_CASE("steady progress is below 1 whenever the rule says not steady, and 1 once it says steady", "[daemon][campaign]") {
    DaemonFixture f;
    REQUIRE(f.daemon().start_campaign(quick_plan("progress")).empty());
    int acquiring_checks = 0, steady_checks = 0, not_steady_checks = 0;
    bool saw_full_window_not_steady = false;
    for (int i = 0; i < 6 * 3600 && f.daemon().campaign_active(); ++i) {
        f.daemon().step_virtual(1.0);
        const auto s = f.daemon().status_json();
        if (s["stage"] != "acquiring" || !s.contains("trial")) continue;
        const auto& t = s["trial"];
        ++acquiring_checks;
        const double progress = t["steady_progress"].get<double>();
        const bool steady = t["steady"].get<bool>();
        INFO("t = " << s["time_s"] << " s: " << t.dump());
        CHECK(t["limit_c"].get<double>() == Approx(0.05));
        CHECK(t["min_duration_s"].get<double>() == Approx(35 * 60));
        CHECK(t["window_filled_fraction"].get<double>() <= 1.0);
        if (steady) {
            ++steady_checks;
            CHECK(progress == 1.0);
            CHECK(t["worst_zone_range_c"].get<double>() < 0.05);
            CHECK(t["elapsed_s"].get<double>() >= 35 * 60);
            CHECK(t["worst_zone"]["zone"].get<int>() >= 1);
            CHECK_FALSE(t["worst_zone"]["name"].get<std::string>().empty());
        } else {
            ++not_steady_checks;
            CHECK(progress < 1.0);
            // The old bar (time in stage over the window) was full here while the rule said no.
            if (t["window_filled_fraction"].get<double>() >= 1.0) saw_full_window_not_steady = true;
        }
    }
    CHECK_FALSE(f.daemon().campaign_active());
    CHECK(acquiring_checks > 35 * 60);
    CHECK(not_steady_checks > 0);
    CHECK(steady_checks > 0);
    CHECK(saw_full_window_not_steady);
}

TEST_CASE("status carries the measured chamber air, RH, air speed, mean skin temperature and heat flux with units and ages",
          "[daemon][campaign]") {
    DaemonFixture f;
    REQUIRE(f.daemon().start_campaign(quick_plan("measured")).empty());
    // Into acquiring: the chamber has settled and the manikin runs.
    for (int i = 0; i < 4 * 3600 && f.daemon().status_json()["stage"] != "acquiring"; ++i) f.daemon().step_virtual(1.0);
    for (int i = 0; i < 60; ++i) f.daemon().step_virtual(1.0);
    REQUIRE(f.daemon().status_json()["stage"] == "acquiring");
    const auto m = f.daemon().status_json()["measured"];
    INFO(m.dump(2));
    CHECK(m["chamber_air_temp_c"]["unit"] == "°C");
    CHECK(m["chamber_air_temp_c"]["setpoint"].get<double>() == Approx(35.0));
    CHECK(m["chamber_air_temp_c"]["value"].get<double>() == Approx(35.0).margin(1.5));
    CHECK(m["chamber_air_temp_c"]["age_s"].get<double>() < 10.0);
    CHECK(m["chamber_air_rh_pct"]["unit"] == "%");
    CHECK(m["chamber_air_rh_pct"]["setpoint"].get<double>() == Approx(27.0));
    CHECK(m["air_speed_m_s"]["unit"] == "m/s");
    CHECK(m["air_speed_m_s"]["value"].is_number());
    CHECK(m["mean_skin_temp_c"]["unit"] == "°C");
    CHECK(m["mean_skin_temp_c"]["value"].get<double>() == Approx(35.0).margin(2.0));
    CHECK(m["mean_skin_temp_c"]["zones_used"].get<int>() > 0);
    CHECK(m["mean_heat_flux_w_m2"]["unit"] == "W/m²");
    const auto live = f.daemon().live_json();
    CHECK(live["windsonic/air_speed_m_s"]["unit"] == "m/s");
    CHECK(live["manikin/z01.skin_temp_c"]["unit"] == "°C");
}

TEST_CASE("campaign files: counts are whole numbers, case ids unique, a dry case does not sweat, names printable", "[daemon][campaign]") {
    const std::string case1 = "[[cases]]\nchamber_temp_c = 35\nchamber_rh_pct = 27\n";
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("name = \"t\"\nreplicates = 2.5\n" + case1, "p.toml"),
                      Catch::Contains("p.toml:2") && Catch::Contains("replicates: 2.5 is not a whole number"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("name = \"t\"\n" + case1 + "id = 4\n" + case1 + "id = 4\n", "p.toml"),
                      Catch::Contains("p.toml:9") && Catch::Contains("cases.id: 4 is already the id of an earlier case"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("name = \"t\"\n" + case1 + "wet = false\nsweat_rate_g_m2_h = 200\n", "p.toml"),
                      Catch::Contains("p.toml:6") && Catch::Contains("on a dry case (wet = false)"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("name = \"a\\u0007b\"\n" + case1, "p.toml"),
                      Catch::Contains("p.toml:1") && Catch::Contains("control character"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("name = \"" + std::string(121, 'x') + "\"\n" + case1, "p.toml"),
                      Catch::Contains("more than the 120 allowed"));
    // The same file with the mistakes put right is accepted.
    const auto plan = manikind::parse_campaign_plan("name = \"t\"\nreplicates = 2\n" + case1 + "id = 4\n" + case1 +
                                                        "id = 5\nwet = true\nsweat_rate_g_m2_h = 200\n",
                                                    "p.toml");
    REQUIRE(plan.cases.size() == 2);
    CHECK(plan.replicates == 2);
    CHECK(plan.cases[1].sweat_rate_g_m2_h == 200);
}

TEST_CASE("a clothing campaign names the standard each test follows with its edition: text, for a test it runs, "
          "stored in its definition (issue 64)", "[daemon][campaign][clothing]") {
    const std::string head = "name = \"t\"\n[ensembles.coat]\ndescription = \"a coat\"\n";
    const std::string cases = "[[cases]]\nchamber_temp_c = 20\nchamber_rh_pct = 50\nskin_setpoint_c = 34\nensemble = \"coat\"\n"
                              "test = \"insulation\"\n";
    CHECK_THROWS_WITH(manikind::parse_campaign_plan(head + cases + "[standards]\ninsulation = 15831\n", "s.toml"),
                      Catch::Contains("s.toml:11") && Catch::Contains("standards.insulation: expected the standard and its edition"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan(head + cases + "[standards]\nthermal = \"ISO 15831:2004\"\n", "s.toml"),
                      Catch::Contains("standards.thermal: unknown key"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan(head + cases + "[standards]\nevaporative = \"ASTM F2370-16\"\n", "s.toml"),
                      Catch::Contains("standards.evaporative: no case runs an evaporative test"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan(head + cases + "[standards]\ninsulation = \"" + std::string(81, 'x') + "\"\n", "s.toml"),
                      Catch::Contains("standards.insulation") && Catch::Contains("80"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("standards = \"ISO\"\n" + head + cases, "s.toml"),
                      Catch::Contains("s.toml:1") && Catch::Contains("standards: expected a table"));
    const auto plan = manikind::parse_campaign_plan(head + cases + "[standards]\ninsulation = \"ISO 15831:2004\"\n", "s.toml");
    CHECK(plan.standards.at("insulation") == "ISO 15831:2004");
    CHECK(manikind::campaign_definition_json(plan)["standards"]["insulation"] == "ISO 15831:2004");
    // A plan without it stores the definition it stored before (continued campaigns compare it).
    CHECK_FALSE(manikind::campaign_definition_json(manikind::parse_campaign_plan(head + cases, "s.toml")).contains("standards"));
}

TEST_CASE("a case states its room where it is not uniform ([[cases.local]]): zones by name, region or segment, every "
          "mistake refused by file, line and key, the room stored with the case (issue 65)", "[daemon][campaign][comfort]") {
    const std::string head = "name = \"t\"\n[[cases]]\nchamber_temp_c = 25\nchamber_rh_pct = 40\n";
    const auto plan = manikind::parse_campaign_plan(head + "[[cases.local]]\nzones = [\"chest\", \"face\"]\nwhat = \"sun\"\n"
                                                           "solar_w_m2 = 120\n[[cases.local]]\nzones = [\"hand\"]\nair_speed_m_s = 1.5\n"
                                                           "air_offset_c = -3\n",
                                                    "room.toml");
    const auto& map = manikind::analysis::andi35_zone_map();
    REQUIRE(plan.cases.front().local.size() == map.size());
    int sunny = 0, jets = 0;
    for (std::size_t z = 0; z < map.size(); ++z) {
        const auto& l = plan.cases.front().local[z];
        const bool chest_or_face = map.zones[z].region == "chest" || map.zones[z].name == "face";
        CHECK(l.solar_w_m2 == (chest_or_face ? 120.0 : 0.0));
        sunny += chest_or_face ? 1 : 0;
        if (map.zones[z].segment == "hand") {
            CHECK(l.air_speed_m_s == 1.5);
            CHECK(l.air_offset_c == -3.0);
            ++jets;
        } else {
            CHECK_FALSE(l.air_speed_m_s.has_value());
        }
    }
    CHECK(sunny >= 2);
    CHECK(jets == 2);
    // Stored with the case: the non-uniform zones by id.
    const auto stored = manikind::case_conditions_json(plan.cases.front())["local"];
    CHECK(stored.size() == static_cast<std::size_t>(sunny + jets));
    std::string why;
    CHECK(manikind::analysis::parse_local_room(map, stored, why) == plan.cases.front().local);
    CHECK(why.empty());
    // A case without it stores what it stored before.
    CHECK_FALSE(manikind::case_conditions_json(manikind::parse_campaign_plan(head, "room.toml").cases.front()).contains("local"));
    auto refused = [&](const std::string& room, const std::string& what) {
        INFO(room);
        CHECK_THROWS_WITH(manikind::parse_campaign_plan(head + room, "room.toml"), Catch::Contains("room.toml:") && Catch::Contains(what));
    };
    refused("[[cases.local]]\nzones = [\"elbow\"]\nsolar_w_m2 = 10\n", "'elbow' is no zone, region or segment");
    refused("[[cases.local]]\nsolar_w_m2 = 10\n", "cases.local.zones: expected the zones");
    refused("[[cases.local]]\nzones = [\"face\"]\nsolar_w_m2 = 5000\n", "cases.local.solar_w_m2: 5000");
    refused("[[cases.local]]\nzones = [\"face\"]\nsolar = 50\n", "cases.local.solar: unknown key");
    refused("[[cases.local]]\nzones = [\"face\"]\nair_speed_m_s = \"fast\"\n", "cases.local.air_speed_m_s: expected a number");
    refused("local = 3\n", "cases.local: expected [[cases.local]] tables");
    // campaign.json's reading of it names the entry and key.
    CHECK(manikind::analysis::parse_local_room(map, nlohmann::json::parse(R"([{"zone": 99, "solar_w_m2": 1}])"), why).empty());
    CHECK_THAT(why, Catch::Contains("[0].zone: 99 is no zone"));
    CHECK(manikind::analysis::parse_local_room(map, nlohmann::json::parse(R"([{"zone": 1, "solar_w_m2": -1}])"), why).empty());
    CHECK_THAT(why, Catch::Contains("[0].solar_w_m2: expected a number within 0..1000"));
    CHECK(manikind::analysis::parse_local_room(map, nlohmann::json::parse(R"({"zone": 1})"), why).empty());
    CHECK_THAT(why, Catch::Contains("expected an array"));
}

TEST_CASE("a misspelt campaign key is refused with file, line, column, key and the nearest known key", "[daemon][campaign]") {
    const std::string text = "name = \"typo\"\nreplicate = 1\nbuiltin_cases = \"table-s3\"\n";
    CHECK_THROWS_WITH(manikind::parse_campaign_plan(text, "typo.toml"),
                      Catch::Contains("typo.toml:2:1") && Catch::Contains("replicate: unknown key") &&
                          Catch::Contains("did you mean 'replicates'?"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("name = \"t\"\n[[cases]]\nchamber_temp_c = 35\nchamber_rh_pct = 27\nwett = true\n",
                                                    "cases.toml"),
                      Catch::Contains("cases.toml:5:1") && Catch::Contains("cases.wett: unknown key") &&
                          Catch::Contains("did you mean 'wet'?"));
    CHECK_THROWS_WITH(manikind::parse_campaign_plan("name = \"t\"\ncolour = \"blue\"\nbuiltin_cases = \"table-s3\"\n", "c.toml"),
                      Catch::Contains("colour: unknown key") && !Catch::Contains("did you mean"));
    CHECK(manikind::edit_distance("replicate", "replicates") == 1);
    CHECK(manikind::edit_distance("kitten", "sitting") == 3);
    // The daemon's start_campaign path parses with the same parser: refused, nothing started.
    DaemonFixture f;
    bool shutdown = false;
    manikind::ControlOptions o;
    o.token = "s3cret";
    const nlohmann::json request = {{"cmd", "start_campaign"}, {"token", "s3cret"}, {"plan_toml", text}, {"source", "typo.toml"}};
    const auto reply = manikind::handle_request(f.daemon(), o, request.dump(), shutdown);
    CHECK_FALSE(reply["ok"].get<bool>());
    const auto error = reply["error"].get<std::string>();
    CHECK(error.find("typo.toml:2:1") != std::string::npos);
    CHECK(error.find("replicate: unknown key") != std::string::npos);
    CHECK(f.daemon().status_json()["campaign"].is_null());
    CHECK_FALSE(f.daemon().db().find_campaign("typo"));
}

TEST_CASE("outside trials the daemon keeps an idle log: one reading per channel per idle_log_period_s, none "
          "during a trial, none when 0",
          "[daemon][campaign][idle]") {
    using manikind::test::DaemonFixture;
    DaemonFixture f([](manikind::config::Config& c) { c.idle_log_period_s = 10.0; });
    for (int i = 0; i < 120; ++i) f.daemon().step_virtual(1.0);
    f.daemon().flush_recorder();
    auto& db = f.daemon().db();
    std::int64_t chamber_pv = -1;
    for (const auto& ch : db.channels())
        if (ch.device_name == "chamber" && ch.name == "air_temp_pv_c") chamber_pv = ch.id;
    REQUIRE(chamber_pv > 0);
    const auto rows = db.idle_samples(chamber_pv, 0);
    // 120 s polled every second, kept every 10 s: 12 readings (the first at once), 10 s apart.
    CHECK(rows.size() >= 11);
    CHECK(rows.size() <= 13);
    for (std::size_t i = 1; i < rows.size(); ++i) CHECK(rows[i].mono_ns - rows[i - 1].mono_ns >= 10'000'000'000LL);
    REQUIRE(f.daemon().start_campaign(manikind::test::quick_plan("idle")).empty());
    f.daemon().step_virtual(1.0);  // the tick at its end creates the trial
    REQUIRE(f.daemon().status_json().contains("trial"));
    f.daemon().flush_recorder();
    const auto trial_began = db.idle_sample_count();
    for (int i = 0; i < 60; ++i) f.daemon().step_virtual(1.0);
    f.daemon().flush_recorder();
    CHECK(db.idle_sample_count() == trial_began);  // a trial's readings go to its samples, not the idle log

    DaemonFixture off([](manikind::config::Config& c) { c.idle_log_period_s = 0.0; });
    for (int i = 0; i < 30; ++i) off.daemon().step_virtual(1.0);
    off.daemon().flush_recorder();
    CHECK(off.daemon().db().idle_sample_count() == 0);
}

TEST_CASE("results so far are stored after each trial, marked interim, with the parity point of every case done",
          "[daemon][campaign]") {
    using manikind::test::DaemonFixture;
    auto c = manikind::config::default_config();
    manikind::test::DaemonFixture f([](manikind::config::Config&) {});
    // A second daemon on its own database, with interim results on the virtual clock.
    const auto dir = f.dir() / "interim";
    std::filesystem::create_directories(dir);
    c.database = dir / "d.db";
    c.simulation.runtime_dir = (dir / "sim").string();
    c.log_level = "error";
    manikind::LabDaemon daemon({c, true, 1.0});
    daemon.set_interim_results(true);
    auto plan = quick_plan("interim");
    plan.cases.push_back({2, 35.0, 27.0, 35.0, false, 0.0, std::nullopt, std::nullopt, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});  // a dry case after the wet one
    REQUIRE(daemon.start_campaign(plan).empty());
    // Step until the first trial has ended, then wait for its analysis (its own thread).
    while (daemon.status_json()["trials_done"].get<int>() < 1) daemon.step_virtual(1.0);
    daemon.stop();  // joins the interim analysis
    const auto interim = daemon.results_json("interim");
    CHECK(interim["interim"] == true);
    REQUIRE(interim["cases"].size() == 1);
    CHECK(interim["cases"][0]["case"] == 1);
    REQUIRE(interim["twin_parity"].size() == 1);
    CHECK(interim["twin_parity"][0]["case"] == 1);
}

TEST_CASE("a chamber that refuses setpoints for 4 min delays the trial instead of failing it, for longer the trial fails and the campaign continues", "[daemon][campaign][faults]") {
    SECTION("4 min of Modbus exceptions at the trial's start: retried, the trial completes") {
        DaemonFixture f([](manikind::config::Config& c) { c.simulation.faults = {"chamber:exception@0-240"}; });
        REQUIRE(f.daemon().start_campaign(manikind::test::quick_plan("glitch")).empty());
        f.daemon().run_virtual();
        auto& db = f.daemon().db();
        const auto trials = db.trials(*db.find_campaign("glitch"));
        REQUIRE(trials.size() == 1);
        CHECK(trials[0].state == "done");
        bool retried = false;
        for (const auto& e : db.events(trials[0].id)) retried |= e.message.find("retrying for up to 5 min") != std::string::npos;
        CHECK(retried);
    }
    SECTION("7 min: the trial fails after 5, the campaign ends; started again it runs that trial and completes") {
        DaemonFixture f([](manikind::config::Config& c) { c.simulation.faults = {"chamber:exception@0-420"}; });
        REQUIRE(f.daemon().start_campaign(manikind::test::quick_plan("outage")).empty());
        f.daemon().run_virtual();
        auto& db = f.daemon().db();
        const auto id = db.find_campaign("outage");
        auto trials = db.trials(*id);
        REQUIRE(trials.size() == 1);
        CHECK(trials[0].state == "failed");
        CHECK(trials[0].reason.find("chamber setpoint refused for 5 min") != std::string::npos);
        for (int s = 0; s < 200; ++s) f.daemon().step_virtual(1.0);  // past the outage
        REQUIRE(f.daemon().start_campaign(manikind::test::quick_plan("outage")).empty());
        f.daemon().run_virtual();
        trials = db.trials(*id);
        REQUIRE(trials.size() == 2);
        CHECK(trials[0].state == "failed");
        CHECK(trials[1].state == "done");
        // Now every planned trial is done: the same plan again is refused as complete.
        CHECK(f.daemon().start_campaign(manikind::test::quick_plan("outage")).find("is complete") != std::string::npos);
    }
}

TEST_CASE("a restarted simulated lab never stamps a time already used: nothing recorded is dropped as a duplicate",
          "[daemon][idle][restart]") {
    // Issue 30: every run on the virtual clock began at 2026-06-01 09:00 UTC, so a second run's
    // idle log met the first run's keys and ~208 k readings were dropped as "already stored".
    const auto dir = std::filesystem::temp_directory_path() / ("manikind-restart-" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    auto config = manikind::config::default_config();
    config.database = dir / "lab.db";
    config.simulation.runtime_dir = (dir / "sim").string();
    config.log_level = "error";
    config.idle_log_period_s = 10.0;
    std::int64_t first_count = 0, first_newest = 0, run_count = 0;
    for (int run = 0; run < 3; ++run) {
        manikind::LabDaemon daemon(manikind::DaemonOptions{config, true, 1.0});
        auto& db = daemon.db();
        const auto before = db.idle_sample_count();
        const auto newest_before = db.newest_utc_ns();
        for (int i = 0; i < 120; ++i) daemon.step_virtual(1.0);
        daemon.flush_recorder();
        const auto added = db.idle_sample_count() - before;
        CHECK(added > 0);
        if (run == 0) {
            first_count = added;
            first_newest = *db.newest_utc_ns();
        } else {
            CHECK(added == first_count);  // the same readings as the first run, none dropped
            REQUIRE(newest_before.has_value());
            // Every reading of this run is later than everything before it.
            std::int64_t chamber_pv = -1;
            for (const auto& ch : db.channels())
                if (ch.device_name == "chamber" && ch.name == "air_temp_pv_c") chamber_pv = ch.id;
            REQUIRE(chamber_pv > 0);
            const auto rows = db.idle_samples(chamber_pv, *newest_before + 1);
            CHECK(rows.size() >= 11);
            CHECK(*db.newest_utc_ns() > first_newest);
        }
        run_count += added;
    }
    {
        auto db = manikind::recorder::Database::open_read_only(config.database);
        CHECK(db.idle_sample_count() == run_count);
    }
    std::filesystem::remove_all(dir);
}

TEST_CASE("a virtual run hands over the campaign its results binned while recording, equal to what the database holds, so the demo reads no reading back",
          "[daemon]") {
    DaemonFixture f;
    REQUIRE(f.daemon().start_campaign(quick_plan("handed")).empty());
    f.daemon().run_virtual();
    const auto handed = f.daemon().take_computed_campaign();
    REQUIRE(handed);
    CHECK_FALSE(f.daemon().take_computed_campaign());  // handed over once
    // Its trial came from the bins kept while recording, not from reading the trial back.
    CHECK(f.daemon().trials_binned_as_recorded() == 1);
    const auto read = manikind::campaign_from_database(f.daemon().db(), "handed");
    CHECK(handed->name == read.name);
    REQUIRE(handed->trials.size() == read.trials.size());
    REQUIRE(handed->trials.size() == 1);
    const auto& a = handed->trials[0].data;
    const auto& b = read.trials[0].data;
    REQUIRE(a.rows() == b.rows());
    CHECK(a.rows() >= 35 * 60 / 5);
    // Value for value, a missing one (NaN) where the other is missing too.
    auto same = [](const std::vector<double>& x, const std::vector<double>& y) {
        if (x.size() != y.size()) return false;
        for (std::size_t i = 0; i < x.size(); ++i)
            if (!(x[i] == y[i] || (std::isnan(x[i]) && std::isnan(y[i])))) return false;
        return true;
    };
    CHECK(same(a.t_s, b.t_s));
    CHECK(same(a.air_temp_c, b.air_temp_c));
    CHECK(same(a.air_rh_pct, b.air_rh_pct));
    REQUIRE(a.heat_flux_w_m2.size() == b.heat_flux_w_m2.size());
    for (std::size_t z = 0; z < a.heat_flux_w_m2.size(); ++z) {
        CHECK(same(a.heat_flux_w_m2[z], b.heat_flux_w_m2[z]));
        CHECK(same(a.skin_temp_c[z], b.skin_temp_c[z]));
    }
    REQUIRE(a.channel_values.size() == b.channel_values.size());
    for (std::size_t k = 0; k < a.channel_values.size(); ++k) CHECK(same(a.channel_values[k], b.channel_values[k]));
    CHECK(a.channel_quality == b.channel_quality);
    CHECK(handed->channels.size() == read.channels.size());
}
