// Clothing tests (issue 33): the definitions of ASTM F1291 / ISO 15831 / ASTM F2370 / ISO 9920
// checked on campaigns built here by hand, the Monte Carlo Type B against the GUM's linear
// propagation, and the recording format's new keys, round trip and hostile input.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include <catch2/catch.hpp>

#include "analysis/analyze.hpp"
#include "analysis/clothing.hpp"
#include "analysis/input_error.hpp"
#include "analysis/recording.hpp"
#include "analysis/zone_map.hpp"
#include "physics/psychrometrics.hpp"
#include "tests/analysis/temp_dir.hpp"

namespace an = manikind::analysis;
namespace cl = manikind::analysis::clothing;

namespace {

// A steady trial: 35 min at 15 s, every zone at its skin temperature and flux, air constant.
an::Trial steady_trial(const an::ZoneMap& map, const std::string& id, int case_id, int replicate, const std::string& ensemble,
                       const std::string& test, double air_c, double rh_pct, const std::vector<double>& skin_c,
                       const std::vector<double>& q_w_m2) {
    an::Trial t;
    t.info.id = id;
    t.info.case_id = case_id;
    t.info.replicate = replicate;
    t.info.file = "trials/" + id + ".csv";
    t.info.ensemble = ensemble;
    t.info.test = test;
    t.info.wettedness = test == "evaporative" ? 1.0 : 0.0;
    const std::size_t rows = 141;
    for (std::size_t k = 0; k < rows; ++k) {
        t.data.t_s.push_back(15.0 * static_cast<double>(k));
        t.data.air_temp_c.push_back(air_c);
        t.data.air_rh_pct.push_back(rh_pct);
        t.data.air_speed_m_s.push_back(0.4);
    }
    t.data.skin_temp_c.resize(map.size());
    t.data.heat_flux_w_m2.resize(map.size());
    for (std::size_t z = 0; z < map.size(); ++z) {
        t.data.skin_temp_c[z].assign(rows, skin_c[z]);
        t.data.heat_flux_w_m2[z].assign(rows, q_w_m2[z]);
    }
    return t;
}

// The nude manikin and one ensemble: per zone total resistances, dry and isothermal wet tests.
struct Lab {
    an::ZoneMap map = an::andi35_zone_map();
    std::vector<double> ia, it, rea, ret;   // per zone, m²K/W and m²kPa/W
    Lab() {
        for (std::size_t z = 0; z < map.size(); ++z) {
            const bool torso = map.zones[z].region == "chest" || map.zones[z].region == "back" || map.zones[z].region == "pelvis";
            ia.push_back(z % 2 ? 0.08 : 0.10);
            it.push_back(ia.back() + (torso ? 0.30 : 0.12));
            rea.push_back(ia.back() / 10.0);
            ret.push_back(rea.back() + (torso ? 0.040 : 0.015));
        }
    }
    an::Campaign campaign(int replicates, std::optional<double> fcl) const {
        an::Campaign c;
        c.name = "clothing-unit";
        c.zone_map = map;
        c.instruments = an::default_instrument_specs();
        c.ensembles["suit"] = {"two-piece suit", fcl};
        const double dp_kpa = (1.0 - 0.4) * manikind::physics::saturation_vapour_pressure_pa(35.0) / 1000.0;
        int case_id = 0;
        for (const std::string ensemble : {"nude", "suit"}) {
            const auto& r_dry = ensemble == "nude" ? ia : it;
            const auto& r_wet = ensemble == "nude" ? rea : ret;
            std::vector<double> skin(map.size(), 35.0), q_dry, q_wet;
            for (std::size_t z = 0; z < map.size(); ++z) {
                q_dry.push_back(15.0 / r_dry[z]);
                q_wet.push_back(dp_kpa / r_wet[z]);
            }
            ++case_id;
            for (int r = 1; r <= replicates; ++r)
                c.trials.push_back(steady_trial(map, fmt("c", case_id, r), case_id, r, ensemble, "insulation", 20.0, 50.0, skin, q_dry));
            ++case_id;
            for (int r = 1; r <= replicates; ++r)
                c.trials.push_back(steady_trial(map, fmt("c", case_id, r), case_id, r, ensemble, "evaporative", 35.0, 40.0, skin, q_wet));
        }
        return c;
    }
    static std::string fmt(const char* p, int c, int r) { return std::string(p) + std::to_string(c) + "-r" + std::to_string(r); }
    // The definitions, computed here from the per-zone resistances.
    double parallel(const std::vector<double>& r) const {
        double g = 0.0;
        for (std::size_t z = 0; z < map.size(); ++z) g += map.zones[z].area_m2 / map.total_area_m2() / r[z];
        return 1.0 / g;
    }
    double serial(const std::vector<double>& r) const {
        double s = 0.0;
        for (std::size_t z = 0; z < map.size(); ++z) s += map.zones[z].area_m2 / map.total_area_m2() * r[z];
        return s;
    }
};

const cl::EnsembleResult& ensemble(const cl::Result& r, const std::string& id) {
    for (const auto& e : r.ensembles)
        if (e.id == id) return e;
    FAIL("no ensemble " << id);
    return r.ensembles.front();
}

}  // namespace

TEST_CASE("clothing: parallel and serial insulation and evaporative resistance follow their definitions, and effective, "
          "intrinsic and im from the nude values (ISO 9920 4.2)", "[clothing]") {
    const Lab lab;
    const auto campaign = lab.campaign(3, 1.3);
    const auto analysis = an::analyze_campaign(campaign);
    cl::Options o;
    o.monte_carlo_draws = 500;
    const auto r = cl::compute(campaign, analysis, nullptr, nullptr, o);
    REQUIRE(r.ensembles.size() == 2);
    CHECK(r.ensembles.front().id == "nude");
    const auto& nude = ensemble(r, "nude");
    const auto& suit = ensemble(r, "suit");
    const double ia = lab.parallel(lab.ia), it = lab.parallel(lab.it), rea = lab.parallel(lab.rea), ret = lab.parallel(lab.ret);
    CHECK(nude.insulation_total_parallel->value == Approx(ia).epsilon(1e-9));
    CHECK(nude.insulation_total_serial->value == Approx(lab.serial(lab.ia)).epsilon(1e-9));
    CHECK(suit.insulation_total_parallel->value == Approx(it).epsilon(1e-9));
    CHECK(suit.insulation_total_serial->value == Approx(lab.serial(lab.it)).epsilon(1e-9));
    // Serial is never below parallel (the harmonic mean is at most the arithmetic one).
    CHECK(suit.insulation_total_serial->value > suit.insulation_total_parallel->value);
    CHECK(suit.evaporative_total_parallel->value == Approx(ret).epsilon(1e-9));
    CHECK(suit.evaporative_total_serial->value == Approx(lab.serial(lab.ret)).epsilon(1e-9));
    CHECK(suit.evaporative_method == "isothermal");
    CHECK(suit.fcl == 1.3);
    CHECK(suit.fcl_source == "given");
    CHECK(suit.insulation_effective_parallel->value == Approx(it - ia).epsilon(1e-9));
    CHECK(suit.insulation_intrinsic_parallel->value == Approx(it - ia / 1.3).epsilon(1e-9));
    CHECK(suit.evaporative_intrinsic_parallel->value == Approx(ret - rea / 1.3).epsilon(1e-9));
    CHECK(suit.permeability_index->value == Approx(it / (16.5 * ret)).epsilon(1e-9));
    // Identical replicates: coefficient of variation 0, criterion passed.
    REQUIRE(suit.insulation_cv.has_value());
    CHECK(*suit.insulation_cv == Approx(0.0).margin(1e-12));
    CHECK(*suit.insulation_cv_pass);
    // Regions: the torso's local insulation is its own parallel value.
    bool chest = false;
    for (const auto& rv : suit.regions)
        if (rv.region == "chest") {
            chest = true;
            REQUIRE(rv.insulation_total.has_value());
            CHECK(rv.insulation_total->value > it);
        }
    CHECK(chest);
}

TEST_CASE("clothing: without a given fcl, ISO 9920's estimate fcl = 1 + 0.28 Icl (clo) is solved with Icl = It - Ia/fcl",
          "[clothing]") {
    const Lab lab;
    const auto campaign = lab.campaign(2, std::nullopt);
    cl::Options o;
    o.monte_carlo_draws = 200;
    const auto r = cl::compute(campaign, an::analyze_campaign(campaign), nullptr, nullptr, o);
    const auto& suit = ensemble(r, "suit");
    const double ia = lab.parallel(lab.ia), it = lab.parallel(lab.it);
    // Bisection on f - 1 - 0.28 (It - Ia/f)/0.155 = 0, independent of the code's fixed point.
    double lo = 1.0, hi = 3.0;
    for (int i = 0; i < 100; ++i) {
        const double mid = 0.5 * (lo + hi);
        (mid - 1.0 - 0.28 * (it - ia / mid) / 0.155 > 0.0 ? hi : lo) = mid;
    }
    CHECK(suit.fcl == Approx(lo).epsilon(1e-9));
    CHECK(suit.fcl_source.find("ISO 9920") != std::string::npos);
}

TEST_CASE("clothing: the Monte Carlo Type B of the total insulation agrees with the GUM's linear propagation", "[clothing]") {
    const Lab lab;
    const auto campaign = lab.campaign(3, 1.3);
    cl::Options o;
    o.monte_carlo_draws = 8000;  // the standard deviation of a standard deviation from 8000 draws: 0.8 %
    const auto r = cl::compute(campaign, an::analyze_campaign(campaign), nullptr, nullptr, o);
    const auto& nude = ensemble(r, "nude");
    // It = dT / q (parallel): u²/It² = u(dT)²/dT² + u(q)²/q², with the skin (±0.1 °C) and air
    // (±0.2 °C) probes' rectangular limits and the flux's offset (±1 W/m²) and gain (±3 %), all
    // shared by the zones (the specs of default_instrument_specs()).
    const double it = nude.insulation_total_parallel->value, q = 15.0 / it;
    const double u_dt = std::sqrt((0.1 * 0.1 + 0.2 * 0.2) / 3.0);
    const double u_q = std::sqrt((1.0 * 1.0 + 0.03 * q * 0.03 * q) / 3.0);
    const double linear = it * std::hypot(u_dt / 15.0, u_q / q);
    CHECK(nude.insulation_total_parallel->u_b == Approx(linear).epsilon(0.03));
    // Identical replicates: no Type A, so k is the normal 1.96 and U = 1.96 u_B.
    CHECK(nude.insulation_total_parallel->k == Approx(1.96).epsilon(0.01));
}

TEST_CASE("clothing: a nude baseline from another campaign, and a campaign without clothing tests is refused with why",
          "[clothing]") {
    const Lab lab;
    auto both = lab.campaign(2, 1.3);
    an::Campaign baseline = both, clothed = both;
    std::erase_if(baseline.trials, [](const an::Trial& t) { return t.info.ensemble != "nude"; });
    std::erase_if(clothed.trials, [](const an::Trial& t) { return t.info.ensemble == "nude"; });
    baseline.name = "nude-baseline";
    cl::Options o;
    o.monte_carlo_draws = 200;
    const auto alone = cl::compute(clothed, an::analyze_campaign(clothed), nullptr, nullptr, o);
    CHECK_FALSE(ensemble(alone, "suit").insulation_effective_parallel.has_value());
    CHECK_FALSE(ensemble(alone, "suit").notes.empty());
    const auto with = cl::compute(clothed, an::analyze_campaign(clothed), &baseline, nullptr, o);  // no analysis: not used
    CHECK_FALSE(ensemble(with, "suit").insulation_effective_parallel.has_value());
    const auto ba = an::analyze_campaign(baseline);
    const auto r = cl::compute(clothed, an::analyze_campaign(clothed), &baseline, &ba, o);
    CHECK(r.baseline == "nude-baseline");
    CHECK(ensemble(r, "suit").insulation_effective_parallel->value ==
          Approx(lab.parallel(lab.it) - lab.parallel(lab.ia)).epsilon(1e-9));
    an::Campaign plain = both;
    for (auto& t : plain.trials) t.info.ensemble.clear();
    CHECK_THROWS_WITH(cl::compute(plain, an::analyze_campaign(plain), nullptr, nullptr, o),
                      Catch::Contains("no clothing test"));
}

TEST_CASE("clothing: ensembles and each trial's ensemble and test survive a write and read, and hostile values are refused "
          "with the field named", "[clothing][recording]") {
    const Lab lab;
    const auto campaign = lab.campaign(1, 1.25);
    manikind::test::TempDir dir;
    an::write_campaign(dir.path, campaign);
    const auto back = an::read_campaign(dir.path);
    REQUIRE(back.ensembles.count("suit") == 1);
    CHECK(back.ensembles.at("suit").description == "two-piece suit");
    CHECK(back.ensembles.at("suit").fcl == 1.25);
    REQUIRE(back.trials.size() == campaign.trials.size());
    for (std::size_t i = 0; i < back.trials.size(); ++i) {
        CHECK(back.trials[i].info.ensemble == campaign.trials[i].info.ensemble);
        CHECK(back.trials[i].info.test == campaign.trials[i].info.test);
    }
    const auto json_path = dir.path / "campaign.json";
    std::stringstream ss;
    ss << std::ifstream(json_path).rdbuf();
    const auto original = nlohmann::json::parse(ss.str());
    auto refused = [&](auto edit, const std::string& field) {
        auto doc = original;
        edit(doc);
        std::ofstream(json_path, std::ios::trunc) << doc.dump(1);
        INFO(field);
        try {
            an::read_campaign(dir.path);
            FAIL("accepted");
        } catch (const an::InputError& e) {
            CHECK_THAT(e.what(), Catch::Contains(field));
        }
    };
    refused([](auto& d) { d["trials"][0]["ensemble"] = 5; }, "trials[0].ensemble");
    refused([](auto& d) { d["trials"][0]["ensemble"] = "tuxedo"; }, "unknown ensemble 'tuxedo'");
    refused([](auto& d) { d["trials"][0]["test"] = "wet"; }, "trials[0].test");
    refused([](auto& d) { d["ensembles"]["nude"] = {{"description", "x"}}; }, "ensembles.nude");
    refused([](auto& d) { d["ensembles"]["suit"]["fcl"] = 0.5; }, "ensembles.suit.fcl");
    refused([](auto& d) { d["ensembles"]["suit"]["fcl"] = "big"; }, "ensembles.suit.fcl");
    refused([](auto& d) { d["ensembles"] = {1, 2}; }, "ensembles");
    refused([](auto& d) { d["ensembles"]["suit"] = 3; }, "ensembles.suit");
}
