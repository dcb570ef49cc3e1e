// Issue 33: a standard clothing test end to end on the simulated lab and the virtual clock. The
// campaign template (config/campaign-clothing-astm.toml) runs through the daemon; the world puts
// on each case's ensemble from its wardrobe (sim/world/wardrobe.cpp) for every trial; the export
// carries the ensembles and each trial's ensemble and test; `manikin clothing`'s computation
// recovers what the world's own physics gives at the recorded conditions, inside its intervals.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "analysis/analyze.hpp"
#include "analysis/clothing.hpp"
#include "daemon/campaign_plan.hpp"
#include "daemon/simulated_lab.hpp"
#include "daemon_fixture.hpp"
#include "physics/psychrometrics.hpp"
#include "physics/twin/twin.hpp"
#include "sim/world/wardrobe.hpp"
#include "store/database_export.hpp"
#include "store/hdf5_export.hpp"

namespace an = manikind::analysis;
namespace tw = manikind::physics::twin;

TEST_CASE("clothing test on the simulated lab: the world wears the wardrobe's ensembles, the export names them, and "
          "the computed insulation and evaporative resistance hold the world's values", "[daemon][clothing][proof]") {
    manikind::test::DaemonFixture f([](manikind::config::Config& c) { c.simulation.air_speed_m_s = 0.4; });
    auto plan = manikind::load_campaign_plan(MANIKIND_CONFIG_DIR "/campaign-clothing-astm.toml");
    plan.replicates = 2;
    plan.trial_duration_s = 40 * 60.0;
    REQUIRE(f.daemon().start_campaign(plan).empty());
    f.daemon().run_virtual();
    auto& db = f.daemon().db();
    for (const auto& t : db.trials(*db.find_campaign(plan.name))) {
        CHECK(t.state == "done");
        // The standards' stop rule (issue 64): each trial ended on a steady whole-body heat loss.
        int stopped_steady = 0;
        for (const auto& e : db.events(t.id))
            if (e.message.find("heat loss steady") != std::string::npos) ++stopped_steady;
        CHECK(stopped_steady == 1);
    }

    // The campaign's stored results carry clo and Ret per ensemble (what manikind prints at its end).
    const auto stored = f.daemon().results_json(plan.name);
    REQUIRE(stored.contains("clothing"));
    CHECK(stored["clothing"]["ensembles"].size() == 3);
    CHECK(stored["clothing"]["ensembles"][1]["insulation"]["total_parallel"]["clo"].is_number());
    const auto campaign = manikind::campaign_from_database(db, plan.name);
    // The standards the template chose, with their editions, as the report prints them (issue 64).
    CHECK(campaign.standards == std::map<std::string, std::string>{{"insulation", "ASTM F1291-16"}, {"evaporative", "ASTM F2370-16"}});
    {
        const auto h5 = f.dir() / "clothing.h5";
        manikind::write_campaign_hdf5(h5, campaign, an::analyze_campaign(campaign));
        CHECK(manikind::hdf5_read_string_attribute(h5, "/", "insulation_standard") == "ASTM F1291-16");
    }
    REQUIRE(campaign.ensembles.count("coverall") == 1);
    CHECK(campaign.ensembles.at("coverall").fcl == 1.26);
    CHECK_FALSE(campaign.ensembles.at("jacket").fcl.has_value());
    REQUIRE(campaign.trials.size() == 12);
    for (const auto& t : campaign.trials) {
        CHECK_FALSE(t.info.ensemble.empty());
        CHECK((t.info.test == "insulation" || t.info.test == "evaporative"));
    }
    // The same rule on the recording, as `manikin clothing` applies it: no trial left out.
    an::AnalysisOptions standard;
    standard.steady.require_heat_loss_stability = true;
    const auto analysis = an::analyze_campaign(campaign, standard);
    const auto r = an::clothing::compute(campaign, analysis, nullptr, nullptr);
    std::string left_out;
    for (const auto& l : r.left_out) left_out += l.trial + ": " + l.reason + "\n";
    INFO(left_out);
    CHECK(r.left_out.empty());
    CHECK(r.without_result.empty());
    CHECK(r.standards == campaign.standards);
    CHECK(an::clothing::to_json(r)["standards"]["insulation"] == "ASTM F1291-16");
    REQUIRE(r.ensembles.size() == 3);

    // What the world's physics gives at each test's recorded conditions (the world's own model,
    // evaluated here from the wardrobe; the recording went through devices, drivers, database,
    // export, steady windows and the computation).
    const auto world = manikind::simulated_lab_options(f.daemon().config()).world;
    const auto map = an::andi35_zone_map();
    auto expected = [&](const std::string& ensemble, const an::clothing::Conditions& c, bool wet) {
        tw::TwinVersion v = world.physics;
        if (ensemble != "nude") {
            const auto e = manikind::sim::wardrobe_ensemble(ensemble);
            REQUIRE(e.has_value());
            v.terms.insert(v.terms.end(), e->garments.begin(), e->garments.end());
        }
        tw::TrialConditions t;
        t.air_temp_c = c.air_temp_c;
        t.air_rh_pct = c.air_rh_pct;
        t.air_speed_m_s = c.air_speed_m_s;
        t.wall_temp_c = c.air_temp_c - world.wall_below_air_c;
        t.wettedness = wet ? 1.0 : 0.0;
        for (const auto& z : map.zones) t.zones.push_back({z.zone, z.segment, z.region, z.area_m2, c.mean_skin_temp_c});
        const auto q = tw::predict(v, t);
        double g = 0.0;
        for (std::size_t i = 0; i < q.size(); ++i) g += map.zones[i].area_m2 / map.total_area_m2() * q[i].q_total_w_m2;
        if (!wet) return (c.mean_skin_temp_c - c.air_temp_c) / g;
        const double dp_kpa = (manikind::physics::saturation_vapour_pressure_pa(c.mean_skin_temp_c) -
                               manikind::physics::vapour_pressure_pa(c.air_temp_c, c.air_rh_pct)) / 1000.0;
        return dp_kpa / g;
    };
    std::map<std::string, double> it, ret;
    for (const auto& e : r.ensembles) {
        INFO(e.id);
        REQUIRE(e.insulation_total_parallel);
        REQUIRE(e.evaporative_total_parallel);
        it[e.id] = expected(e.id, *e.insulation_conditions, false);
        ret[e.id] = expected(e.id, *e.evaporative_conditions, true);
        std::printf("clothing lab %s: It %.4f ± %.4f (world %.4f), Ret %.4f ± %.4f (world %.4f) m²kPa/W\n", e.id.c_str(),
                    e.insulation_total_parallel->value, e.insulation_total_parallel->U95, it[e.id],
                    e.evaporative_total_parallel->value, e.evaporative_total_parallel->U95, ret[e.id]);
        CHECK(std::abs(e.insulation_total_parallel->value - it[e.id]) <= e.insulation_total_parallel->U95);
        CHECK(std::abs(e.evaporative_total_parallel->value - ret[e.id]) <= e.evaporative_total_parallel->U95);
        // Ventilated chamber: the tests ran at the standards' 0.4 m/s.
        CHECK(e.insulation_conditions->air_speed_m_s == Approx(0.4).margin(0.05));
    }
    // Clothes insulate: the jacket more than the coverall, both more than the bare manikin.
    CHECK(it["jacket"] > it["coverall"]);
    CHECK(it["coverall"] > it["nude"]);
    for (const char* id : {"coverall", "jacket"}) {
        const auto& e = *std::find_if(r.ensembles.begin(), r.ensembles.end(), [&](const auto& x) { return x.id == id; });
        REQUIRE(e.insulation_effective_parallel);
        const double icle = it[id] - it["nude"];
        CHECK(std::abs(e.insulation_effective_parallel->value - icle) <= e.insulation_effective_parallel->U95);
        const double icl = it[id] - it["nude"] / e.fcl;
        CHECK(std::abs(e.insulation_intrinsic_parallel->value - icl) <= e.insulation_intrinsic_parallel->U95);
    }
}
