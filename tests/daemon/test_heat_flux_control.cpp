// Issue 65: the manikin's constant-heat-flux and comfort control modes. Each zone's heating is fixed (a region
// may have its own), its skin temperature measured: the campaign file's keys and their mistakes,
// the safety limit, and a trial on the simulated lab where every zone's skin settles where the
// world's physics loses exactly the heat given.
#include <catch2/catch.hpp>

#include <cmath>
#include <algorithm>
#include <fstream>
#include <iterator>
#include <string>

#include <fmt/format.h>

#include "analysis/analyze.hpp"
#include "analysis/plot/svg_figure.hpp"
#include "analysis/recording.hpp"
#include "analysis/teq.hpp"
#include "daemon/config.hpp"
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
    (void)f.run_one_done_trial(plan);
    RanTrial out{manikind::campaign_from_database(f.daemon().db(), plan.name), {}};
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

namespace {
std::string read_config_file(const std::string& name) {
    std::ifstream in(std::string(MANIKIND_CONFIG_DIR) + "/" + name);
    REQUIRE(in.good());
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
// A campaign of the shipped templates run to its end on a lab's virtual clock, read back as a lab would.
manikind::analysis::Campaign run_template(manikind::test::DaemonFixture& f, const std::string& name) {
    const auto plan = manikind::parse_campaign_plan(read_config_file(name), name);
    REQUIRE(f.daemon().start_campaign(plan).empty());
    f.daemon().run_virtual();
    return manikind::campaign_from_database(f.daemon().db(), plan.name);
}
// The world's own teq of one zone (ISO 14505-2's definition, not the method): the temperature of a
// uniform room, air = walls and still, in which the world's physics takes from the zone at its
// skin temperature the heat the cabin takes. The loss falls as the room warms: bisection.
double world_teq_c(const manikind::sim::WorldOptions& world, const manikind::analysis::Zone& zone, std::size_t index,
                   double skin_c, double air_c, double wall_c, double rh_pct, double speed_m_s) {
    namespace tw = manikind::physics::twin;
    auto loss = [&](double room_air_c, double room_wall_c, double speed, bool local) {
        tw::TrialConditions c;
        c.air_temp_c = room_air_c;
        c.wall_temp_c = room_wall_c;
        c.air_rh_pct = rh_pct;
        c.air_speed_m_s = speed;
        c.zones = {{zone.zone, zone.segment, zone.region, zone.area_m2, skin_c}};
        if (local) c.zones[0].local = world.local.at(index);
        return tw::predict(world.physics, c).at(0).q_total_w_m2;
    };
    const double cabin_w_m2 = loss(air_c, wall_c, speed_m_s, true);
    double lo = -20.0, hi = skin_c + 20.0;
    for (int i = 0; i < 60; ++i) {
        const double mid = 0.5 * (lo + hi);
        (loss(mid, mid, 0.01, false) > cabin_w_m2 ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}
}  // namespace

TEST_CASE("a car cabin on the simulated lab (the shipped templates): calibrated in a uniform chamber, each zone's teq in "
          "comfort mode and at constant heat flux holds the world's own teq within its U95, and the modes differ only as the "
          "world's teq does",
          "[daemon][comfort][teq][proof]") {
    namespace teq = manikind::analysis::teq;
    // The calibration, in the uniform chamber.
    manikind::test::DaemonFixture uniform([](manikind::config::Config& c) {
        c = manikind::config::parse_config(read_config_file("sim-uniform-calibration.toml"), "sim-uniform-calibration.toml", c);
    });
    const auto cal_campaign = run_template(uniform, "campaign-teq-calibration.toml");
    const auto cal = teq::calibrate(cal_campaign, manikind::analysis::analyze_campaign(cal_campaign), teq::Limits{});
    // The cabin: the same manikin in the summer cabin's room.
    manikind::test::DaemonFixture cabin([](manikind::config::Config& c) {
        c = manikind::config::parse_config(read_config_file("sim-car-cabin-summer.toml"), "sim-car-cabin-summer.toml", c);
    });
    const auto world = manikind::simulated_lab_options(cabin.daemon().config()).world;
    REQUIRE(world.local.size() == 35);
    const auto campaign = run_template(cabin, "campaign-cabin-teq.toml");
    const auto analysis = manikind::analysis::analyze_campaign(campaign);
    std::string left_out;
    for (const auto& cs : analysis.cases)
        for (const auto& t : cs.trials)
            if (!t.included) left_out += " " + t.id + ": " + t.exclusion_reason + ";";
    for (const auto& cs : analysis.unanalysed_cases)
        for (const auto& u : cs.trials) left_out += " " + u.id + ": " + u.steady.reason + ";";
    INFO("trials left out:" << left_out);
    REQUIRE(analysis.cases.size() == 2);
    const auto result = teq::compute(campaign, analysis, cal, teq::placeholder_ranges(campaign.zone_map));
    REQUIRE(result.cases.size() == 2);
    const auto& map = campaign.zone_map;

    int inside = 0, zones = 0, agree = 0;
    double lowest = 99.0, highest = -99.0, widest = 0.0;
    std::string misses, widest_zone;
    std::vector<std::vector<double>> world_truth(2, std::vector<double>(map.size())), skin_of = world_truth;
    std::vector<double> u95s;
    double largest_world_difference = 0.0;
    for (std::size_t k = 0; k < 2; ++k) {
        const auto& cs = analysis.cases[k];
        const auto& teq_case = result.cases[k];
        REQUIRE(teq_case.replicates == 2);
        for (std::size_t z = 0; z < map.size(); ++z) {
            double skin = 0.0, air = 0.0, wall = 0.0, rh = 0.0, speed = 0.0;
            for (const auto& t : cs.trials) {
                skin += t.zone_skin_temp_c[z] / 2.0;
                air += t.air_temp_c / 2.0;
                wall += t.wall_temp_c / 2.0;
                rh += t.air_rh_pct / 2.0;
                speed += t.air_speed_m_s / 2.0;
            }
            const double truth = world_teq_c(world, map.zones[z], z, skin, air, wall, rh, speed);
            world_truth[k][z] = truth;
            skin_of[k][z] = skin;
            const auto& v = teq_case.zones[z].teq;
            ++zones;
            if (std::abs(v.value - truth) <= v.U95) ++inside;
            else misses += fmt::format(" case {} {} {:.2f} ± {:.2f} (world {:.2f});", cs.case_id, map.zones[z].name, v.value, v.U95, truth);
            lowest = std::min(lowest, truth);
            highest = std::max(highest, truth);
            if (v.U95 > widest) widest_zone = fmt::format("case {} {} (u_A {:.2f}, u_B {:.2f} K)", cs.case_id, map.zones[z].name, v.u_a, v.u_b);
            widest = std::max(widest, v.U95);
            u95s.push_back(v.U95);
        }
    }
    for (std::size_t z = 0; z < map.size(); ++z) {
        const auto &a = result.cases[0].zones[z].teq, &b = result.cases[1].zones[z].teq;
        // teq is the room's alone where the exchange is linear in the skin's temperature; under the
        // sun (a fixed gain) and a jet it is not, and the world's own teq moves with the skin the
        // mode holds (comfort mode's skin is the one ISO 14505-2 wants). The modes must differ as
        // the world's teq does, within their intervals.
        const double world_difference = world_truth[0][z] - world_truth[1][z];
        largest_world_difference = std::max(largest_world_difference, std::abs(world_difference));
        if (std::abs(a.value - b.value - world_difference) <= std::hypot(a.U95, b.U95)) ++agree;
        else
            misses += fmt::format(" {} comfort {:.2f} ± {:.2f} (world {:.2f}, skin {:.2f}), flux {:.2f} ± {:.2f} (world {:.2f}, skin {:.2f});",
                                  map.zones[z].name, a.value, a.U95, world_truth[0][z], skin_of[0][z], b.value, b.U95, world_truth[1][z],
                                  skin_of[1][z]);
    }
    INFO("world teq " << lowest << " .. " << highest << " °C; widest U95 " << widest << " K at " << widest_zone << "; inside " << inside << " of " << zones
                      << "; the modes agree at " << agree << " of 35 zones; misses:" << misses);
    std::sort(u95s.begin(), u95s.end());
    const double median_u95 = u95s[u95s.size() / 2];
    INFO("median U95 " << median_u95 << " K; the world's teq differs between the modes by up to " << largest_world_difference << " K");
    CHECK(highest - lowest > 8.0);            // a non-uniform room: the zones' teq spread widely
    CHECK(inside >= 0.9 * zones);             // 95 % intervals, 70 zones that share one lab's errors
    CHECK(agree >= 33);                       // the modes differ as the world's own teq does
    CHECK(largest_world_difference > 0.3);    // ... and under the sun it does (docs/comfort.md)
    CHECK(median_u95 < 1.0);                  // two replicates: a zone whose pair disagrees has few dof and a wide U95
    // The whole body's teq lies within the zones', and the diagram draws both cases.
    for (const auto& c : result.cases) CHECK((c.whole_body.teq.value > lowest - 1.0 && c.whole_body.teq.value < highest + 1.0));
    const auto svg = manikind::analysis::plot::to_svg(teq::comfort_figure(result));
    CHECK(svg.find("face") != std::string::npos);

    // Exported as a folder (the modes named in each trial) and read back, teq gives the same numbers.
    const auto folder = cabin.dir() / "cabin-export";
    manikind::export_campaign(cabin.daemon().db(), campaign.name, folder);
    const auto read_back = manikind::analysis::read_campaign(folder);
    REQUIRE(read_back.trials.size() == 4);
    CHECK(read_back.trials[0].info.control == "comfort");
    const auto again = teq::compute(read_back, manikind::analysis::analyze_campaign(read_back), cal, teq::placeholder_ranges(map));
    CHECK(again.cases.at(1).whole_body.teq.value == Approx(result.cases[1].whole_body.teq.value).margin(0.02));
}
