// Issue 65: the manikin's constant-heat-flux and comfort control modes. Each zone's heating is fixed (a region
// may have its own), its skin temperature measured: the campaign file's keys and their mistakes,
// the safety limit, and a trial on the simulated lab where every zone's skin settles where the
// world's physics loses exactly the heat given.
#include <catch2/catch.hpp>

#include <cmath>
#include <string>

#include "analysis/analyze.hpp"
#include "base/user_error.hpp"
#include "daemon/campaign_plan.hpp"
#include "daemon/comfort_loop.hpp"
#include "daemon/simulated_lab.hpp"
#include "daemon_fixture.hpp"
#include "physics/twin/twin.hpp"
#include "store/database_export.hpp"

namespace {
const std::string flux_plan_header = "name = \"flux\"\nreplicates = 1\ntrial_duration_min = 40\n";

std::string flux_plan_refusal(const std::string& cases) {
    try {
        (void)manikind::parse_campaign_plan(flux_plan_header + cases, "flux.toml");
    } catch (const manikind::UserError& e) {
        return e.what();
    }
    return "accepted";
}
// One case of the plan run on the simulated lab's virtual clock: it must end done and its one
// trial be steady and used (why not, when it is not).
struct RanTrial {
    manikind::analysis::Campaign campaign;
    manikind::analysis::CampaignResult analysis;
    const manikind::analysis::TrialResult& trial() const { return analysis.cases.at(0).trials.at(0); }
};
RanTrial run_one_case(manikind::test::DaemonFixture& f, const std::string& cases) {
    const auto plan = manikind::parse_campaign_plan(flux_plan_header + cases, "flux.toml");
    REQUIRE(f.daemon().start_campaign(plan).empty());
    f.daemon().run_virtual();
    auto& db = f.daemon().db();
    const auto trials = db.trials(*db.find_campaign(plan.name));
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "done");
    RanTrial out{manikind::campaign_from_database(db, plan.name), {}};
    out.analysis = manikind::analysis::analyze_campaign(out.campaign);
    std::string why;
    for (const auto& c : out.analysis.unanalysed_cases)
        for (const auto& u : c.trials) why += u.id + ": " + u.steady.reason + "\n";
    INFO(why);
    REQUIRE(out.analysis.cases.size() == 1);
    REQUIRE(out.analysis.cases[0].trials.size() == 1);
    REQUIRE(out.trial().included);
    return out;
}
}  // namespace

TEST_CASE("constant heat flux: the case's keys parse, and every mistake is refused by file, line and key",
          "[daemon][comfort]") {
    const auto plan = manikind::parse_campaign_plan(
        flux_plan_header + "[[cases]]\nid = 1\nchamber_temp_c = 20\nchamber_rh_pct = 40\ncontrol = \"constant-heat-flux\"\n"
                 "heat_flux_w_m2 = 60\nheat_flux_by_region_w_m2 = { head = 80, hand_l = 90 }\n",
        "flux.toml");
    REQUIRE(plan.cases.size() == 1);
    REQUIRE(plan.cases[0].heat_flux_w_m2.has_value());
    CHECK(*plan.cases[0].heat_flux_w_m2 == 60.0);
    CHECK(plan.cases[0].heat_flux_by_region_w_m2.at("head") == 80.0);
    CHECK(manikind::case_conditions_json(plan.cases[0])["control"] == "constant-heat-flux");

    const std::string base = "[[cases]]\nid = 1\nchamber_temp_c = 20\nchamber_rh_pct = 40\n";
    CHECK_THAT(flux_plan_refusal(base + "control = \"constant-heat-flux\"\n"), Catch::Contains("flux.toml:4") && Catch::Contains("needs heat_flux_w_m2"));
    CHECK_THAT(flux_plan_refusal(base + "control = \"constant-heat-flux\"\nheat_flux_w_m2 = 60\nskin_setpoint_c = 34\n"),
               Catch::Contains("flux.toml:10") && Catch::Contains("measured, not set"));
    CHECK_THAT(flux_plan_refusal(base + "heat_flux_w_m2 = 60\n"), Catch::Contains("cases.heat_flux_w_m2") &&
                                                           Catch::Contains("is for control = \"constant-heat-flux\""));
    CHECK_THAT(flux_plan_refusal(base + "control = \"constant-heat-flux\"\nheat_flux_w_m2 = -5\n"), Catch::Contains("outside 0..1000"));
    CHECK_THAT(flux_plan_refusal(base + "control = \"constant-heat-flux\"\nheat_flux_w_m2 = 60\nheat_flux_by_region_w_m2 = { tail = 5 }\n"),
               Catch::Contains("no such region") && Catch::Contains("head"));
    CHECK_THAT(flux_plan_refusal(base + "control = \"comfy\"\n"), Catch::Contains("\"constant-heat-flux\""));

    // The daemon's limit: heating above safety.max_heater_power_w_m2 is refused before the start.
    auto hot = plan;
    hot.cases[0].heat_flux_by_region_w_m2["head"] = 900.0;
    manikind::config::SafetyLimits limits;
    CHECK_THAT(manikind::check_plan_against_limits(hot, limits), Catch::Contains("max_heater_power_w_m2"));
    CHECK(manikind::check_plan_against_limits(plan, limits).empty());
}

TEST_CASE("constant heat flux on the simulated lab: every zone is heated at its setpoint and its skin settles where the "
          "world's physics loses that heat", "[daemon][comfort][proof]") {
    manikind::test::DaemonFixture f;
    const auto ran = run_one_case(f, "[[cases]]\nid = 1\nchamber_temp_c = 24\nchamber_rh_pct = 40\ncontrol = \"constant-heat-flux\"\n"
                                     "heat_flux_w_m2 = 45\nheat_flux_by_region_w_m2 = { head = 60 }\n");
    const auto& campaign = ran.campaign;
    const auto& t = ran.trial();
    const auto world = manikind::simulated_lab_options(f.daemon().config()).world;
    const auto& map = campaign.zone_map;
    double lowest_skin = 99.0, highest_skin = 0.0;
    for (std::size_t z = 0; z < map.size(); ++z) {
        const double set_w_m2 = map.zones[z].region == "head" ? 60.0 : 45.0;
        INFO("zone " << map.zones[z].zone << " " << map.zones[z].name);
        // The heating is what was asked (the recorded flux is the heaters' power).
        CHECK(t.zone_q_w_m2[z] == Approx(set_w_m2).margin(1.5));
        // The skin floats: at the world's steady state its own loss at that skin equals the heating.
        manikind::physics::twin::TrialConditions c;
        c.air_temp_c = t.air_temp_c;
        c.air_rh_pct = t.air_rh_pct;
        c.wall_temp_c = t.wall_temp_c;
        c.air_speed_m_s = t.air_speed_m_s;
        c.zones = {{map.zones[z].zone, map.zones[z].segment, map.zones[z].region, map.zones[z].area_m2, t.zone_skin_temp_c[z]}};
        const double loss = manikind::physics::twin::predict(world.physics, c).at(0).q_total_w_m2;
        CHECK(loss == Approx(set_w_m2).margin(0.15 * set_w_m2));
        lowest_skin = std::min(lowest_skin, t.zone_skin_temp_c[z]);
        highest_skin = std::max(highest_skin, t.zone_skin_temp_c[z]);
    }
    INFO("skin " << lowest_skin << " .. " << highest_skin << " °C");
    CHECK(highest_skin - lowest_skin > 0.5);  // not a skin setpoint: each zone where its own exchange puts it
}

TEST_CASE("comfort mode: the coefficients parse with their defaults, and mistakes are refused by file, line and key",
          "[daemon][comfort]") {
    const std::string base = "[[cases]]\nid = 1\nchamber_temp_c = 20\nchamber_rh_pct = 40\n";
    const auto plan = manikind::parse_campaign_plan(flux_plan_header + base + "control = \"comfort\"\n", "flux.toml");
    REQUIRE(plan.cases[0].comfort.has_value());
    CHECK(plan.cases[0].comfort->a_c == 36.4);
    CHECK(plan.cases[0].comfort->b_c_m2_w == 0.054);
    CHECK(plan.cases[0].comfort->skin_c(50.0) == Approx(33.7));
    CHECK(manikind::case_conditions_json(plan.cases[0])["control"] == "comfort");
    const auto own = manikind::parse_campaign_plan(flux_plan_header + base + "control = \"comfort\"\ncomfort_a_c = 36\ncomfort_b_c_m2_w = 0.05\n",
                                                   "flux.toml");
    CHECK(own.cases[0].comfort->a_c == 36.0);
    CHECK_THAT(flux_plan_refusal(base + "control = \"comfort\"\nskin_setpoint_c = 34\n"),
               Catch::Contains("flux.toml:9") && Catch::Contains("follows its own heat loss"));
    CHECK_THAT(flux_plan_refusal(base + "comfort_a_c = 36\n"), Catch::Contains("is for control = \"comfort\""));
    CHECK_THAT(flux_plan_refusal(base + "control = \"comfort\"\ncomfort_b_c_m2_w = 3\n"), Catch::Contains("outside 0..0.2"));
}

TEST_CASE("comfort mode loop: each zone's setpoint moves towards a - b q of its own measured loss at no more than the "
          "allowed rate, from where the zone is", "[daemon][comfort]") {
    const auto& map = manikind::analysis::andi35_zone_map();
    manikind::config::PhysiologicalConfig limits;
    manikind::ComfortLoop loop({36.4, 0.054}, limits, map);
    manikind::LoopInputs in;
    in.zones.resize(map.size());
    for (std::size_t z = 0; z < map.size(); ++z) in.zones[z] = {34.0, z < 3 ? 100.0 : 40.0, 0, true, false};
    auto first = loop.tick(in);
    REQUIRE(first.size() == map.size());
    CHECK(first[0].skin_setpoint_c == Approx(34.0));  // from where it is: no jump
    // Twenty steps later the head zones (100 W/m²) head for 31.0 °C, the others for 34.24 °C.
    for (int i = 1; i <= 40; ++i) {
        in.now_ns = static_cast<std::int64_t>(i * limits.coupling_period_s * 1e9);
        for (auto& r : in.zones) r.flux_mono_ns = in.now_ns;
        const auto out = loop.tick(in);
        REQUIRE(out.size() == map.size());
        if (i == 1) CHECK(out[0].skin_setpoint_c == Approx(34.0 - limits.max_setpoint_rate_c_min * limits.coupling_period_s / 60.0));
    }
    CHECK(loop.zone_setpoints_c()[0] == Approx(36.4 - 0.054 * 100.0));
    CHECK(loop.zone_setpoints_c()[10] == Approx(36.4 - 0.054 * 40.0));
    // Not a step between periods.
    in.now_ns += 1'000'000'000;
    CHECK(loop.tick(in).empty());
}

TEST_CASE("comfort mode on the simulated lab: every zone's skin settles on the comfort equation of its own heat loss",
          "[daemon][comfort][proof]") {
    manikind::test::DaemonFixture f;
    const auto ran = run_one_case(f, "[[cases]]\nid = 1\nchamber_temp_c = 22\nchamber_rh_pct = 40\ncontrol = \"comfort\"\n");
    const auto& campaign = ran.campaign;
    const auto& t = ran.trial();
    double worst = 0.0, lowest = 99.0, highest = 0.0;
    for (std::size_t z = 0; z < campaign.zone_map.size(); ++z) {
        worst = std::max(worst, std::abs(t.zone_skin_temp_c[z] - (36.4 - 0.054 * t.zone_q_w_m2[z])));
        lowest = std::min(lowest, t.zone_skin_temp_c[z]);
        highest = std::max(highest, t.zone_skin_temp_c[z]);
    }
    INFO("largest departure from t_sk = 36.4 - 0.054 q: " << worst << " °C; skin " << lowest << " .. " << highest);
    CHECK(worst < 0.1);
    CHECK(highest - lowest > 0.3);  // the zones that lose more are cooler
}
