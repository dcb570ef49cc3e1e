// Issue 31: a lab day that goes right. Chamber settling by criteria (on target, stable, an ETA;
// a timeout alarms and holds), limits that fit the manikin (config check, campaign check with the
// twin's heater demand), ends that are clear (who aborted and why, standby, the outcome and the
// daemon's exit status).
#include <catch2/catch.hpp>

#include <optional>
#include <utility>

#include <sys/wait.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "daemon/campaign_plan.hpp"
#include "daemon/config.hpp"
#include "daemon_fixture.hpp"
#include "daemon_process.hpp"

using manikind::test::DaemonFixture;
namespace fs = std::filesystem;

namespace {

bool has_event(manikind::LabDaemon& d, const std::string& kind, const std::string& part) {
    for (const auto& e : d.db().events(std::nullopt))
        if (e.kind == kind && e.message.find(part) != std::string::npos) return true;
    return false;
}

std::string stage_of(manikind::LabDaemon& d) { return d.status_json()["stage"].get<std::string>(); }

}  // namespace

TEST_CASE("settling: the manikin starts only with the enclosure on target and stable, and status says what is awaited",
          "[daemon][settling]") {
    DaemonFixture f;
    auto& d = f.daemon();
    auto plan = manikind::test::quick_plan("settle");
    plan.cases.front().chamber_temp_c = 24.0;  // not a Table S3 setpoint: the target is the setpoint
    plan.cases.front().chamber_rh_pct = 45.0;
    plan.cases.front().enclosure_temp_c = 24.0;
    plan.cases.front().enclosure_rh_pct = 45.0;
    plan.cases.front().wet = false;
    plan.cases.front().sweat_rate_g_m2_h = 0;
    REQUIRE(d.start_campaign(plan).empty());
    double air_at_start = 0.0;
    bool saw_settling = false, saw_eta = false, named_air = false, named_window = false;
    std::optional<std::pair<int, double>> first_eta;  // (step, ETA s) made with the air still > 1 K off
    int step = 0;
    for (; step < 4 * 3600 && stage_of(d) != "manikin_starting" && stage_of(d) != "acquiring"; ++step) {
        d.step_virtual(1.0);
        const auto st = d.status_json();
        if (st["stage"] != "chamber_settling") continue;
        const auto& s = st["trial"]["settling"];
        saw_settling = true;
        CHECK(s["target_air_c"] == 24.0);
        CHECK(s["criterion"].get<std::string>().find("within 0.5 °C of 24 °C") != std::string::npos);
        saw_eta = saw_eta || s["eta_s"].is_number();
        if (s["air_c"].is_number()) air_at_start = s["air_c"].get<double>();
        // What still fails is named: the air while off target, the window once on it.
        for (const auto& why : s["failing"]) {
            named_air = named_air || why.get<std::string>().starts_with("air ");
            named_window = named_window || why.get<std::string>().starts_with("on target ");
        }
        // The ETA 10 min into settling, its 5-min history full (the chamber's first minutes are
        // slower than a first-order approach), the air still over 1 K off.
        if (!first_eta && step >= 600 && s["eta_s"].is_number() && s["air_off_c"].is_number() &&
            std::abs(s["air_off_c"].get<double>()) > 1.0)
            first_eta = {step, s["eta_s"].get<double>()};
    }
    CHECK(saw_settling);
    CHECK(saw_eta);
    CHECK(named_air);
    CHECK(named_window);
    // That ETA against when the manikin really started: 1274 s for 1522 (a line through the same
    // minutes said 23 min for 45 in the audit); within 35 %.
    REQUIRE(first_eta);
    const double actual_s = step - first_eta->first, predicted_s = first_eta->second;
    std::printf("settling ETA at %d s: %.0f s, actual %.0f s\n", first_eta->first, predicted_s, actual_s);
    CHECK(std::abs(predicted_s - actual_s) <= 0.35 * actual_s);
    REQUIRE((stage_of(d) == "manikin_starting" || stage_of(d) == "acquiring"));
    // The reason the manikin started names where the enclosure was: within the tolerance.
    bool on_target = false;
    for (const auto& e : d.db().events(std::nullopt))
        if (e.kind == "stage_reason" && e.message.starts_with("enclosure on target: ")) {
            const double air = std::stod(e.message.substr(std::string("enclosure on target: ").size()));
            on_target = std::abs(air - 24.0) <= 0.5;
        }
    CHECK(on_target);
    (void)air_at_start;
}

TEST_CASE("settling: an enclosure that cannot reach its target raises an alarm at the timeout and holds",
          "[daemon][settling]") {
    DaemonFixture f;
    auto& d = f.daemon();
    auto plan = manikind::test::quick_plan("unreachable");
    plan.cases.front().enclosure_temp_c = plan.cases.front().chamber_temp_c + 3.0;  // the chamber never gets it there
    plan.settle_timeout_s = 1800.0;
    REQUIRE(d.start_campaign(plan).empty());
    for (int i = 0; i < 2400; ++i) d.step_virtual(1.0);
    CHECK(stage_of(d) == "chamber_settling");  // held: never acquiring off target
    CHECK(d.status_json()["trial"]["settling"]["timed_out"] == true);
    bool alarm = false;
    for (const auto& a : d.alarms_json()) alarm = alarm || a.value("kind", "") == "settle_timeout";
    CHECK(alarm);
    CHECK(d.campaign_active());
}

TEST_CASE("abort: who and why are recorded, the lab goes to standby, and the outcome says aborted", "[daemon][abort]") {
    DaemonFixture f([](manikind::config::Config& c) {
        c.standby.chamber_temp_c = 21.0;
        c.standby.chamber_rh_pct = 40.0;
    });
    auto& d = f.daemon();
    REQUIRE(d.start_campaign(manikind::test::quick_plan("stopped")).empty());
    for (int i = 0; i < 120; ++i) d.step_virtual(1.0);
    REQUIRE(d.abort("probe fell off", "user alice (uid 1000, pid 42) on the control socket").empty());
    CHECK_FALSE(d.campaign_active());
    CHECK(has_event(d, "abort", "'stopped' aborted by user alice (uid 1000, pid 42) on the control socket: probe fell off"));
    CHECK(has_event(d, "standby", "heating off, chamber 21 °C, 40 %"));
    const auto outcome = d.campaign_outcome_json("stopped");
    CHECK(outcome["state"] == "aborted");
    CHECK(outcome["ok"] == false);
    // The chamber was sent to standby: its setpoint is what the world now heads for.
    for (int i = 0; i < 60; ++i) d.step_virtual(1.0);
    CHECK(d.acquisition().chamber().status().connected);
    const auto trials = d.db().trials(*d.db().find_campaign("stopped"));
    REQUIRE(trials.size() == 1);
    CHECK(trials.front().state == "aborted");
    CHECK(trials.front().reason.find("by user alice") != std::string::npos);
}

TEST_CASE("a campaign done with every trial done has outcome ok, and standby follows its end", "[daemon][abort]") {
    DaemonFixture f;
    auto& d = f.daemon();
    REQUIRE(d.start_campaign(manikind::test::quick_plan("fine")).empty());
    d.run_virtual();
    const auto outcome = d.campaign_outcome_json("fine");
    CHECK(outcome["state"] == "done");
    CHECK(outcome["ok"] == true);
    CHECK(has_event(d, "standby", "campaign 'fine' done: heating off, chamber 23 °C, 45 %"));
}

TEST_CASE("limits that fit the manikin: a heater limit below the heaters' rating is refused with both numbers",
          "[daemon][limits]") {
    auto c = manikind::config::default_config();
    std::vector<std::string> problems;
    manikind::config::check_limits_fit_devices(c, problems);
    CHECK(problems.empty());  // the shipped limits fit the shipped manikin
    c.safety.max_heater_power_w_m2 = 500.0;
    manikind::config::check_limits_fit_devices(c, problems);
    REQUIRE(problems.size() == 1);
    CHECK(problems.front().find("500 W/m² is below the manikin's heater rating") != std::string::npos);
    CHECK(problems.front().find("= 600 W/m²") != std::string::npos);
    c = manikind::config::default_config();
    c.standby.chamber_temp_c = 60.0;
    problems.clear();
    manikind::config::check_limits_fit_devices(c, problems);
    CHECK(problems.size() == 1);
}

TEST_CASE("limits that fit the manikin: standard clothing-test conditions pass the shipped configuration, and a case the "
          "heaters cannot hold is refused before any heating",
          "[daemon][limits]") {
    const auto c = manikind::config::default_config();
    manikind::CampaignPlan plan;
    plan.name = "clothing";
    // ISO 15831 insulation (20 °C air, 35 °C skin, dry); ISO 11092-like isothermal (35 °C, wet);
    // the paper's Table S3 cases.
    plan.cases.push_back({1, 20.0, 50.0, 35.0, false, 0.0, 20.0, 50.0, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});
    plan.cases.push_back({2, 35.0, 40.0, 35.0, true, 300.0, 35.0, 40.0, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});
    CHECK(manikind::check_plan_against_limits(plan, c.safety).empty());
    CHECK(manikind::check_plan_against_devices(plan, c).empty());
    CHECK(manikind::check_plan_against_devices(manikind::table_s3_plan("s3"), c).empty());
    // 35 °C skin, wet, in 5 °C air at 10 % RH: beyond what 600 W/m² heaters hold.
    plan.cases.push_back({3, 5.0, 10.0, 35.0, true, 300.0, 5.0, 10.0, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});
    const auto why = manikind::check_plan_against_devices(plan, c);
    CHECK(why.find("case 3: holding 35 °C skin wet at 5 °C, 10 % RH needs about") != std::string::npos);
    CHECK(why.find("more than the heaters' rating of 600 W/m²") != std::string::npos);
    // And the daemon refuses to start it.
    DaemonFixture f;
    CHECK(f.daemon().start_campaign(plan) == why);
}

TEST_CASE("manikind --exit-when-done exits 6 when the campaign ends aborted, 0 when done", "[daemon][abort][process]") {
    const fs::path dir = fs::temp_directory_path() / ("manikind-exit-status-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    {
        std::ofstream plan(dir / "plan.toml");
        plan << "name = \"ends\"\nreplicates = 1\ntrial_duration_min = 35\nsettle_window_min = 1\n"
                "[[cases]]\nchamber_temp_c = 35\nchamber_rh_pct = 27\nskin_setpoint_c = 35\nwet = false\n";
        // The manikin goes silent mid-trial: the watchdog stops heating and aborts the campaign.
        std::ofstream cfg(dir / "lab.toml");
        cfg << "[simulation]\nfaults = [\"manikin:silent@1500\"]\nruntime_dir = \"" << (dir / "sim").string() << "\"\n";
    }
    const std::string bin = std::string(MANIKIND_BIN_DIR) + "/manikind";
    auto aborted = manikind::test::DaemonProcess::spawn({bin, "--virtual", "--config", (dir / "lab.toml").string(), "--database",
                                                         (dir / "a.db").string(), "--socket", (dir / "a.sock").string(),
                                                         "--campaign", (dir / "plan.toml").string(), "--exit-when-done"});
    const int status = aborted.wait();
    CHECK(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 6);
    auto done = manikind::test::DaemonProcess::spawn({bin, "--virtual", "--database", (dir / "b.db").string(), "--socket",
                                                      (dir / "b.sock").string(), "--campaign", (dir / "plan.toml").string(),
                                                      "--exit-when-done"});
    const int ok = done.wait();
    CHECK(WIFEXITED(ok));
    CHECK(WEXITSTATUS(ok) == 0);
    fs::remove_all(dir);
}

TEST_CASE("excursion: the enclosure off target while acquiring flags the trial, alarms, and restarts the steady window",
          "[daemon][settling]") {
    DaemonFixture f;
    auto& d = f.daemon();
    auto plan = manikind::test::quick_plan("excursion");
    plan.settle_window_s = 60.0;
    REQUIRE(d.start_campaign(plan).empty());
    for (int i = 0; i < 4 * 3600 && stage_of(d) != "acquiring"; ++i) d.step_virtual(1.0);
    REQUIRE(stage_of(d) == "acquiring");
    for (int i = 0; i < 600; ++i) d.step_virtual(1.0);
    const double filled_before = d.status_json()["trial"]["window_filled_fraction"].get<double>();
    CHECK(filled_before > 0.2);
    // Someone turns the chamber down mid-trial: the enclosure leaves its target.
    REQUIRE(d.set_chamber(30.0, 27.0).empty());
    bool alarm = false;
    for (int i = 0; i < 1800 && !alarm; ++i) {
        d.step_virtual(1.0);
        for (const auto& a : d.alarms_json()) alarm = alarm || a.value("kind", "") == "excursion";
    }
    CHECK(alarm);
    REQUIRE(d.set_chamber(35.0, 27.0).empty());  // and back
    bool back = false;
    for (int i = 0; i < 3 * 3600 && !back; ++i) {
        d.step_virtual(1.0);
        back = has_event(d, "excursion", "back on target");
    }
    REQUIRE(back);
    CHECK(d.status_json()["trial"]["window_filled_fraction"].get<double>() < 0.05);  // the window starts again
    const auto trials = d.db().trials(*d.db().find_campaign("excursion"));
    REQUIRE(trials.size() == 1);
    CHECK((trials.front().quality_flags & manikind::flag_enclosure_excursion) != 0);
}
