// Clothing tests (issue 33): the definitions of ASTM F1291 / ISO 15831 / ASTM F2370 / ISO 9920
// checked on campaigns built here by hand, the Monte Carlo Type B against the GUM's linear
// propagation, and the recording format's new keys, round trip and hostile input.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include <catch2/catch.hpp>

#include <fmt/core.h>

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
                       const std::vector<double>& q_w_m2, double speed_m_s = 0.4) {
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
        t.data.air_speed_m_s.push_back(speed_m_s);
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
        c.ensembles["suit"] = {"two-piece suit", fcl, std::nullopt};
        const double dp_kpa = (1.0 - 0.4) * manikind::physics::saturation_vapour_pressure_iapws_pa(35.0) / 1000.0;  // nature's (IAPWS)
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
    // One test of one ensemble at given conditions, every zone at `skin_c`: the insulation test's
    // flux is dry, the wet test's evaporative (fully wet skin) plus the dry part (skin - air)/It_z
    // that ASTM F2370's non-isothermal option removes.
    void add_test(an::Campaign& c, const std::string& ensemble, const std::string& test, int replicates, double skin_c,
                  double air_c, double rh_pct, double speed_m_s = 0.4) const {
        const auto& r_dry = ensemble == "nude" ? ia : it;
        const auto& r_wet = ensemble == "nude" ? rea : ret;
        const double dp_kpa = (manikind::physics::saturation_vapour_pressure_iapws_pa(skin_c) -
                               rh_pct / 100.0 * manikind::physics::saturation_vapour_pressure_iapws_pa(air_c)) / 1000.0;
        std::vector<double> skin(map.size(), skin_c), q;
        for (std::size_t z = 0; z < map.size(); ++z)
            q.push_back((test == "evaporative" ? dp_kpa / r_wet[z] : 0.0) + (skin_c - air_c) / r_dry[z]);
        const int case_id = static_cast<int>(c.trials.size()) + 100;
        for (int r = 1; r <= replicates; ++r)
            c.trials.push_back(steady_trial(map, fmt("t", case_id, r), case_id, r, ensemble, test, air_c, rh_pct, skin, q, speed_m_s));
    }
    an::Campaign empty_campaign(std::optional<double> fcl) const {
        an::Campaign c;
        c.name = "clothing-unit";
        c.zone_map = map;
        c.instruments = an::default_instrument_specs();
        c.ensembles["suit"] = {"two-piece suit", fcl, std::nullopt};
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
    CHECK(suit.evaporative_method.rfind("isothermal (", 0) == 0);
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
    // The report's body map scale follows the data (issue 63): its top is each ensemble's largest
    // local value rounded up to half a clo (at least 1), printed beside the colour bar.
    const auto html = cl::to_html(r, lab.map);
    for (const auto& e : r.ensembles) {
        double top = 0.0;
        for (const auto& rv : e.regions)
            if (rv.insulation_total) top = std::max(top, rv.insulation_total->value / cl::kClo_m2k_w);
        const double scale = std::max(1.0, std::ceil(top * 2.0 - 1e-9) / 2.0);
        INFO(e.id << ": largest local " << top << " clo");
        CHECK(scale >= top);
        CHECK(scale - top < 0.5 + 1e-9 + (top < 1.0 ? 1.0 : 0.0));
        CHECK_THAT(html, Catch::Contains(fmt::format(R"(font-size="11">{:g}</text>)", scale)));
    }
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
    auto campaign = lab.campaign(1, 1.25);
    campaign.standards = {{"insulation", "ISO 15831:2004"}, {"evaporative", "ASTM F2370-16"}};  // the plan's [standards]
    manikind::test::TempDir dir;
    an::write_campaign(dir.path, campaign);
    const auto back = an::read_campaign(dir.path);
    CHECK(back.standards == campaign.standards);
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
    refused([](auto& d) { d["standards"]["insulation"] = 15831; }, "standards.insulation");
    refused([](auto& d) { d["standards"]["thermal"] = "ISO 15831"; }, "standards.thermal");
    refused([](auto& d) { d["standards"]["insulation"] = std::string(81, 'x'); }, "standards.insulation");
    refused([](auto& d) { d["standards"] = "ISO"; }, "standards");
    refused([](auto& d) { d["ensembles"]["suit"] = 3; }, "ensembles.suit");
}

// Issue 63 (a): fcl is never a silent default.
TEST_CASE("clothing: a wet test without an insulation test and no given fcl gets no Recl and says fcl has no source",
          "[clothing]") {
    const Lab lab;
    auto campaign = lab.empty_campaign(std::nullopt);
    lab.add_test(campaign, "nude", "insulation", 2, 35.0, 20.0, 50.0);
    lab.add_test(campaign, "nude", "evaporative", 2, 35.0, 35.0, 40.0);
    lab.add_test(campaign, "suit", "evaporative", 2, 35.0, 35.0, 40.0);
    cl::Options o;
    o.monte_carlo_draws = 200;
    const auto r = cl::compute(campaign, an::analyze_campaign(campaign), nullptr, nullptr, o);
    const auto& suit = ensemble(r, "suit");
    REQUIRE(suit.evaporative_total_parallel.has_value());
    CHECK(suit.evaporative_total_parallel->value == Approx(lab.parallel(lab.ret)).epsilon(1e-9));
    // Before: fcl 1.0 called "ISO 9920 estimate" and Recl = Ret - Rea, 10-13 % low for real ensembles.
    CHECK_FALSE(suit.evaporative_intrinsic_parallel.has_value());
    CHECK(suit.fcl_source.find("ISO 9920") == std::string::npos);
    const auto j = cl::to_json(r);
    const auto& js = j.at("ensembles").at(1);
    CHECK(js.at("fcl").is_null());
    CHECK(js.at("fcl_source") == "none");
    CHECK_THAT(js.at("fcl_reason").get<std::string>(), Catch::Contains("no insulation test"));
    CHECK(js.at("evaporative").at("intrinsic_parallel").is_null());
    CHECK_THAT(js.at("evaporative").at("intrinsic_withheld_reason").get<std::string>(), Catch::Contains("needs fcl"));
    CHECK_THAT(cl::to_text(r), Catch::Contains("fcl none: not given in campaign.json"));
    CHECK_THAT(cl::to_text(r), Catch::Contains("Recl withheld"));
}

TEST_CASE("clothing: ISO 9920's fcl estimate stops at Icl 2 clo and says so and its uncertainty enters U of Icl and Recl",
          "[clothing]") {
    cl::Options o;
    o.monte_carlo_draws = 300;
    SECTION("an ordinary ensemble: the estimate with u(fcl) 0.05") {
        const Lab lab;
        const auto campaign = lab.campaign(2, std::nullopt);
        const auto r = cl::compute(campaign, an::analyze_campaign(campaign), nullptr, nullptr, o);
        const auto& suit = ensemble(r, "suit");
        CHECK(suit.fcl_source == "ISO 9920 estimate");
        CHECK_FALSE(suit.fcl_capped);
        CHECK(suit.fcl_u == 0.05);
        const double ia = lab.parallel(lab.ia), rea = lab.parallel(lab.rea), f = suit.fcl;
        CHECK(suit.insulation_intrinsic_parallel->u_b >= ia / (f * f) * 0.05);
        CHECK(suit.evaporative_intrinsic_parallel->u_b >= rea / (f * f) * 0.05);
        // The given fcl carries none (campaign.json has no uncertainty for it): Icl's u_B is the instruments' alone.
        const auto given = lab.campaign(2, f);
        const auto rg = cl::compute(given, an::analyze_campaign(given), nullptr, nullptr, o);
        CHECK(ensemble(rg, "suit").insulation_intrinsic_parallel->u_b < suit.insulation_intrinsic_parallel->u_b);
        CHECK(cl::to_json(r).at("ensembles").at(1).at("fcl_u") == 0.05);
        CHECK(cl::to_json(rg).at("ensembles").at(1).at("fcl_u").is_null());
    }
    SECTION("a heavy ensemble beyond 2 clo: fcl between the cap's 1.56 and ISO 9920's own, the middle, rectangular") {
        Lab lab;
        for (auto& x : lab.it) x += 0.35;
        const auto campaign = lab.campaign(2, std::nullopt);
        const auto r = cl::compute(campaign, an::analyze_campaign(campaign), nullptr, nullptr, o);
        const auto& suit = ensemble(r, "suit");
        const double it = lab.parallel(lab.it), ia = lab.parallel(lab.ia);
        REQUIRE((it - ia / 1.56) / 0.155 > 2.0);  // uncapped the estimate would go past 1.56
        double iso = 1.0;  // ISO 9920's own fixed point, computed here
        for (int i = 0; i < 200; ++i) iso = 1.0 + 0.28 * (it - ia / iso) / 0.155;
        REQUIRE(iso > 1.7);
        CHECK(suit.fcl == Approx(0.5 * (1.56 + iso)).epsilon(1e-6));
        CHECK(suit.fcl_capped);
        CHECK(suit.fcl_u == Approx(std::max(0.10, (iso - 1.56) / std::sqrt(12.0))).epsilon(1e-6));
        CHECK_THAT(suit.fcl_reason, Catch::Contains("capped at Icl = 2 clo") && Catch::Contains("beyond its range") &&
                                        Catch::Contains("measure fcl"));
        CHECK(suit.insulation_intrinsic_parallel->value == Approx(it - ia / suit.fcl).epsilon(1e-9));
        CHECK(suit.insulation_intrinsic_parallel->u_b >= ia / (suit.fcl * suit.fcl) * suit.fcl_u);
        CHECK(cl::to_json(r).at("ensembles").at(1).at("fcl_capped") == true);
    }
}

// Issue 63 (b): the isothermal judgement. The wet test's flux holds the dry part (skin - air)/It_z.
TEST_CASE("clothing: a wet test within 0.5 K of isothermal without It warns with its bias bound and beyond it Ret is withheld "
          "unless the ensemble's It removes the dry heat", "[clothing]") {
    const Lab lab;
    cl::Options o;
    o.monte_carlo_draws = 200;
    const double ret = lab.parallel(lab.ret), it = lab.parallel(lab.it), ia = lab.parallel(lab.ia);
    auto run = [&](double gap_k, bool suit_insulation) {
        auto c = lab.empty_campaign(1.3);
        lab.add_test(c, "nude", "insulation", 2, 35.0, 20.0, 50.0);
        lab.add_test(c, "nude", "evaporative", 2, 35.0, 35.0, 40.0);
        if (suit_insulation) lab.add_test(c, "suit", "insulation", 2, 35.0, 20.0, 50.0);
        lab.add_test(c, "suit", "evaporative", 2, 35.0, 35.0 - gap_k, 40.0);
        return cl::compute(c, an::analyze_campaign(c), nullptr, nullptr, o);
    };
    auto has_warning = [](const cl::Result& r, const std::string& text) {
        return std::any_of(r.warnings.begin(), r.warnings.end(), [&](const auto& w) { return w.find(text) != std::string::npos; });
    };
    SECTION("0.3 K without It: Ret kept with the dry heat in it and its bound from Ia stated") {
        const auto r = run(0.3, false);
        const auto& suit = ensemble(r, "suit");
        REQUIRE(suit.evaporative_total_parallel.has_value());
        const double measured = suit.evaporative_total_parallel->value;
        const double dp_kpa = (manikind::physics::saturation_vapour_pressure_iapws_pa(35.0) -
                               0.40 * manikind::physics::saturation_vapour_pressure_iapws_pa(34.7)) / 1000.0;
        // Parallel, uniform gap: Ret_measured/Ret - 1 = -(gap/It) Ret_measured/dp exactly.
        CHECK(measured / ret - 1.0 == Approx(-0.3 / it * measured / dp_kpa).epsilon(1e-6));
        REQUIRE(suit.evaporative_dry_bias_bound.has_value());
        CHECK(*suit.evaporative_dry_bias_bound == Approx(-0.3 / ia * measured / dp_kpa).epsilon(1e-9));
        CHECK(*suit.evaporative_dry_bias_bound <= measured / ret - 1.0);  // It >= Ia: the bound holds
        CHECK(has_warning(r, "the dry heat stays in Ret"));
        CHECK_THAT(suit.evaporative_method, Catch::Contains("dry part not removed"));
        CHECK(cl::to_json(r).at("ensembles").at(1).at("evaporative").at("dry_bias_bound").is_number());
    }
    SECTION("0.8 K without It: no Ret and no interval, the reason in text and JSON") {
        const auto r = run(0.8, false);
        const auto& suit = ensemble(r, "suit");
        CHECK_FALSE(suit.evaporative_total_parallel.has_value());
        CHECK_FALSE(suit.evaporative_total_serial.has_value());
        CHECK_FALSE(suit.evaporative_intrinsic_parallel.has_value());
        for (const auto& rv : suit.regions) CHECK_FALSE(rv.evaporative_total.has_value());
        CHECK_THAT(suit.evaporative_withheld_reason, Catch::Contains("beyond the isothermal tolerance 0.5 K"));
        const auto j = cl::to_json(r).at("ensembles").at(1).at("evaporative");
        CHECK(j.at("total_parallel").is_null());
        CHECK(j.at("withheld_reason").is_string());
        CHECK_THAT(cl::to_text(r), Catch::Contains("Ret withheld: skin - air +0.80 K"));
        CHECK(has_warning(r, "suit: Ret withheld"));
    }
    SECTION("0.3 K and 0.8 K with the ensemble's It: the dry part is removed and Ret is the truth") {
        for (double gap : {0.3, 0.8}) {
            const auto r = run(gap, true);
            const auto& suit = ensemble(r, "suit");
            REQUIRE(suit.evaporative_total_parallel.has_value());
            CHECK(suit.evaporative_total_parallel->value == Approx(ret).epsilon(1e-9));
            CHECK_FALSE(suit.evaporative_dry_bias_bound.has_value());
            CHECK_THAT(suit.evaporative_method, Catch::Contains("dry part removed with the ensemble's It"));
            CHECK_FALSE(has_warning(r, "Ret"));
        }
    }
}

// Issue 63 (c): every condition the standard sets, per test, pass or out of range with the value.
TEST_CASE("clothing: each test's conditions are checked against the standard's and shown in text JSON and the report",
          "[clothing]") {
    const Lab lab;
    auto c = lab.empty_campaign(1.3);
    lab.add_test(c, "nude", "insulation", 2, 34.0, 20.0, 50.0);         // ISO 15831's 34 °C skin: pass
    lab.add_test(c, "nude", "evaporative", 2, 35.0, 35.0, 40.0);        // F2370 isothermal: pass
    lab.add_test(c, "suit", "insulation", 2, 35.0, 25.0, 80.0, 0.8);   // 10 K below, 80 % RH, 0.8 m/s
    lab.add_test(c, "suit", "evaporative", 2, 36.0, 36.0, 55.0);        // skin 36 °C, 55 % RH
    cl::Options o;
    o.monte_carlo_draws = 200;
    const auto r = cl::compute(c, an::analyze_campaign(c), nullptr, nullptr, o);
    auto status = [&](const std::string& id, const std::string& test, const std::string& quantity) {
        const auto& e = ensemble(r, id);
        for (const auto& ch : test == "insulation" ? e.insulation_checks : e.evaporative_checks)
            if (ch.quantity == quantity) return ch.status;
        return std::string("missing");
    };
    for (const char* q : {"mean skin temperature", "air below mean skin", "relative humidity", "air speed"})
        CHECK(status("nude", "insulation", q) == "pass");
    for (const char* q : {"mean skin temperature", "skin - air", "relative humidity", "air speed"})
        CHECK(status("nude", "evaporative", q) == "pass");
    CHECK(status("suit", "insulation", "mean skin temperature") == "pass");
    CHECK(status("suit", "insulation", "air below mean skin") == "out of range");
    CHECK(status("suit", "insulation", "relative humidity") == "out of range");
    CHECK(status("suit", "insulation", "air speed") == "out of range");
    CHECK(status("suit", "evaporative", "mean skin temperature") == "out of range");
    CHECK(status("suit", "evaporative", "skin - air") == "pass");
    CHECK(status("suit", "evaporative", "relative humidity") == "out of range");
    const auto text = cl::to_text(r);
    CHECK_THAT(text, Catch::Contains("check relative humidity 80 %: OUT OF RANGE (30-70 %"));
    CHECK_THAT(text, Catch::Contains("check air below mean skin 10.00 K: OUT OF RANGE (at least 12 K"));
    CHECK_THAT(text, Catch::Contains("check mean skin temperature 34.0 °C: pass"));
    CHECK_THAT(text, Catch::Contains("check mean skin temperature 36.0 °C: OUT OF RANGE (35 ± 0.5 °C"));
    const auto j = cl::to_json(r).at("ensembles").at(1);
    const auto& rh = j.at("insulation").at("checks").at(2);
    CHECK(rh.at("quantity") == "relative humidity");
    CHECK(rh.at("value").get<double>() == Approx(80.0));
    CHECK(rh.at("status") == "out of range");
    CHECK(j.at("evaporative").at("checks").size() == 4);
    const auto html = cl::to_html(r, lab.map);
    CHECK_THAT(html, Catch::Contains("<td class=num>80.00 %</td><td class=fail>out of range</td>"));
    CHECK(std::count_if(r.warnings.begin(), r.warnings.end(),
                        [](const auto& w) { return w.find("out of range") != std::string::npos; }) == 5);
}

namespace {
// The suit's insulation test with re-dressings that change its flux by these factors, and the
// nude manikin's with `nude_replicates` identical trials.
an::Campaign redressed(const Lab& lab, const std::vector<double>& fit, int nude_replicates) {
    an::Campaign c = lab.empty_campaign(1.2);
    lab.add_test(c, "nude", "insulation", nude_replicates, 35.0, 20.0, 50.0);
    std::vector<double> skin(lab.map.size(), 35.0);
    for (std::size_t r = 0; r < fit.size(); ++r) {
        std::vector<double> q;
        for (std::size_t z = 0; z < lab.map.size(); ++z) q.push_back(15.0 / lab.it[z] * fit[r]);
        c.trials.push_back(steady_trial(lab.map, Lab::fmt("s", 7, static_cast<int>(r + 1)), 7, static_cast<int>(r + 1), "suit",
                                        "insulation", 20.0, 50.0, skin, q));
    }
    return c;
}
}  // namespace

TEST_CASE("clothing: a 1-replicate nude keeps the 3-replicate ensemble's own Type A in Icle and Icl (issue 63: all of it "
          "was dropped)", "[clothing]") {
    const Lab lab;
    const auto c = redressed(lab, {0.97, 1.0, 1.03}, 1);
    const auto a = an::analyze_campaign(c);
    const auto r = cl::compute(c, a, nullptr, nullptr);
    const auto& suit = ensemble(r, "suit");
    REQUIRE(suit.insulation_total_parallel);
    REQUIRE(suit.insulation_effective_parallel);
    REQUIRE(suit.insulation_intrinsic_parallel);
    REQUIRE(std::isfinite(suit.insulation_total_parallel->u_a));
    CHECK(suit.insulation_total_parallel->u_a > 0.0);
    // Icle = It - Ia: the nude part has none, the ensemble's is all of it.
    CHECK(suit.insulation_effective_parallel->u_a == Approx(suit.insulation_total_parallel->u_a).epsilon(1e-12));
    CHECK(suit.insulation_intrinsic_parallel->u_a == Approx(suit.insulation_total_parallel->u_a).epsilon(1e-12));
    CHECK(suit.insulation_effective_parallel->dof < 1e6);  // finite: the replicates' n - 1 in Welch-Satterthwaite
    CHECK(suit.insulation_effective_parallel->k > 2.0);
}

TEST_CASE("clothing: at one replicate the re-dressing scatter carried from an earlier test with replicates is Type A, and "
          "without it the result says its interval excludes re-dressing", "[clothing]") {
    const Lab lab;
    const auto earlier = redressed(lab, {0.96, 1.0, 1.04}, 3);
    const auto earlier_result = cl::compute(earlier, an::analyze_campaign(earlier), nullptr, nullptr);
    const auto scatter = cl::redressing_scatter(earlier_result);
    REQUIRE(scatter.dressed.count("It_par") == 1);
    // The suit's It over the three fits: 1/0.96, 1, 1/1.04 of the truth; its relative sd.
    const double m = (1 / 0.96 + 1 + 1 / 1.04) / 3;
    const double sd = std::sqrt((std::pow(1 / 0.96 - m, 2) + std::pow(1 - m, 2) + std::pow(1 / 1.04 - m, 2)) / 2) / m;
    CHECK(scatter.dressed.at("It_par").first == Approx(sd).epsilon(1e-9));
    CHECK(scatter.dressed.at("It_par").second == Approx(2.0));
    CHECK(scatter.source == "clothing-unit");

    const auto once = redressed(lab, {1.0}, 1);
    const auto once_result = an::analyze_campaign(once);
    const auto plain = cl::compute(once, once_result, nullptr, nullptr);
    const auto& bare = ensemble(plain, "suit");
    CHECK_FALSE(std::isfinite(bare.insulation_total_parallel->u_a));
    CHECK_THAT(bare.notes.back(), Catch::Contains("excludes re-dressing") && Catch::Contains("--redress-from"));

    cl::Options o;
    o.redressing = scatter;
    const auto carried = cl::compute(once, once_result, nullptr, nullptr, o);
    const auto& suit = ensemble(carried, "suit");
    CHECK(suit.insulation_total_parallel->u_a == Approx(suit.insulation_total_parallel->value * sd).epsilon(1e-9));
    CHECK(suit.insulation_total_parallel->k > 2.5);  // the pooled 2 dof in Welch-Satterthwaite
    CHECK(suit.insulation_total_parallel->U95 > bare.insulation_total_parallel->U95 * 2.0);
    CHECK_THAT(suit.notes.back(), Catch::Contains("carried from clothing-unit"));
    CHECK(cl::to_json(carried)["redressing_from"]["source"] == "clothing-unit");
    // Every unit printed has its U95 (issue 63: none in m²Pa/W).
    const auto it_json = cl::to_json(carried)["ensembles"][1]["insulation"]["total_parallel"];
    CHECK(it_json["U95_clo"].get<double>() == Approx(it_json["U95"].get<double>() / cl::kClo_m2k_w));

    // A test with no replicates has nothing to carry.
    CHECK_THROWS_WITH(cl::redressing_scatter(plain), Catch::Contains("no ensemble has two replicates"));
}

TEST_CASE("clothing: the standards' stop rule: a heat loss still moving over the window leaves its trial out, the "
          "table says so per ensemble, and an ensemble with no trial left has no result but a line", "[clothing]") {
    // The rule alone: a heat loss 3.0 % below its final value at the window's start, easing in.
    {
        std::vector<double> t, q, skin;
        for (int k = 0; k <= 360; ++k) {
            t.push_back(5.0 * k);
            q.push_back(100.0 * (1.0 + 0.06 * std::exp(-5.0 * k / 1200.0)));
            skin.push_back(35.0);
        }
        const auto v = an::judge_heat_loss(t, q, skin, an::HeatLossRule{});
        INFO(v.failing);
        CHECK(v.observed);
        CHECK(v.drift_fraction > 0.03);
        CHECK_FALSE(v.steady);
        CHECK_THAT(v.failing, Catch::Contains("whole-body heat loss moves") && Catch::Contains("limit 3.0 %"));
        for (auto& x : q) x = 100.0 + (x - 100.0) / 4.0;  // a quarter of it: 0.8 % or so
        CHECK(an::judge_heat_loss(t, q, skin, an::HeatLossRule{}).steady);
        for (std::size_t k = 0; k < skin.size(); ++k) skin[k] = 35.0 + 0.15 * static_cast<double>(k) / 360.0;
        CHECK_THAT(an::judge_heat_loss(t, q, skin, an::HeatLossRule{}).failing, Catch::Contains("mean skin temperature moves"));
    }
    const Lab lab;
    an::Campaign c = lab.campaign(2, 1.2);
    // Every trial of the suit's wet test still warming: its flux climbs 6 % over the window.
    for (auto& t : c.trials)
        if (t.info.ensemble == "suit" && t.info.test == "evaporative")
            for (auto& zone : t.data.heat_flux_w_m2)
                for (std::size_t k = 0; k < zone.size(); ++k) zone[k] *= 1.0 + 0.06 * t.data.t_s[k] / 1800.0;
    an::AnalysisOptions standard;
    standard.steady.require_heat_loss_stability = true;
    const auto r = cl::compute(c, an::analyze_campaign(c, standard), nullptr, nullptr);
    REQUIRE(r.left_out.size() == 2);
    CHECK(r.left_out[0].ensemble == "suit");
    CHECK(r.left_out[0].test == "evaporative");
    CHECK_THAT(r.left_out[0].reason, Catch::Contains("heat loss still moving"));
    CHECK(r.without_result.empty());  // its insulation test stands
    const std::string text = cl::to_text(r);
    CHECK_THAT(text, Catch::Contains("LEFT OUT: c4-r1 (evaporative test): not steady: heat loss still moving"));
    CHECK(cl::to_json(r)["left_out"].size() == 2);
    const auto ret_json = cl::to_json(r)["ensembles"][0]["evaporative"]["total_parallel"];
    CHECK(ret_json["U95_m2pa_w"].get<double>() == Approx(1000.0 * ret_json["U95"].get<double>()));
    // The same recordings judged by skin temperature alone keep every trial.
    CHECK(cl::compute(c, an::analyze_campaign(c), nullptr, nullptr).left_out.empty());

    // Every trial of the suit drifting: no result for it, and a line that says so.
    for (auto& t : c.trials)
        if (t.info.ensemble == "suit" && t.info.test == "insulation")
            for (auto& zone : t.data.heat_flux_w_m2)
                for (std::size_t k = 0; k < zone.size(); ++k) zone[k] *= 1.0 - 0.06 * t.data.t_s[k] / 1800.0;
    const auto none = cl::compute(c, an::analyze_campaign(c, standard), nullptr, nullptr);
    CHECK(none.without_result == std::vector<std::string>{"suit"});
    CHECK_THAT(cl::to_text(none), Catch::Contains("suit: NO RESULT: every trial of it was left out"));
}

TEST_CASE("clothing: a given fcl with its uncertainty (fcl_u) widens U of Icl, and one without says it is left out "
          "(issue 63: a given fcl's uncertainty was in no term)", "[clothing]") {
    const Lab lab;
    an::Campaign c = lab.campaign(3, 1.2);
    const auto a = an::analyze_campaign(c);
    const auto without = cl::compute(c, a, nullptr, nullptr);
    c.ensembles["suit"].fcl_u = 0.05;
    const auto with = cl::compute(c, a, nullptr, nullptr);
    const auto& s0 = ensemble(without, "suit");
    const auto& s1 = ensemble(with, "suit");
    CHECK_THAT(s0.fcl_reason, Catch::Contains("left out of U"));
    CHECK_THAT(s1.fcl_reason, Catch::Contains("u(fcl) = 0.05"));
    REQUIRE(s0.insulation_intrinsic_parallel);
    REQUIRE(s1.insulation_intrinsic_parallel);
    // Icl = It - Ia/fcl moves by Ia/fcl^2 per unit fcl.
    const double ia = ensemble(with, "nude").insulation_total_parallel->value;
    const double expected_u_b = std::hypot(s0.insulation_intrinsic_parallel->u_b, ia / (1.2 * 1.2) * 0.05);
    CHECK(s1.insulation_intrinsic_parallel->u_b == Approx(expected_u_b).epsilon(1e-9));
    CHECK(s1.insulation_total_parallel->U95 == Approx(s0.insulation_total_parallel->U95));  // It does not use fcl
    // The recording format round-trips it and refuses it without a given fcl.
    CHECK(an::ensembles_json(c.ensembles)["suit"]["fcl_u"] == 0.05);
}

TEST_CASE("clothing: with the skin fabric's resistance given, the skin's vapour pressure is taken at the wet fabric's "
          "surface, q R below the sensor, and Ret follows its definition there", "[clothing]") {
    const Lab lab;
    const an::Campaign c = lab.campaign(2, 1.2);
    const auto a = an::analyze_campaign(c);
    cl::Options o;
    o.fabric_resistance_m2k_w = 0.01;
    const auto at_sensor = cl::compute(c, a, nullptr, nullptr);
    const auto at_surface = cl::compute(c, a, nullptr, nullptr, o);
    const auto& nude = ensemble(at_surface, "nude");
    REQUIRE(nude.evaporative_total_parallel);
    // The definition at the surface: (sum f p_sat(T - q R) - p_a) / sum f q, the nude wet test's fluxes.
    const double dp_kpa = (1.0 - 0.4) * manikind::physics::saturation_vapour_pressure_iapws_pa(35.0) / 1000.0;
    double ps = 0.0, q = 0.0;
    for (std::size_t z = 0; z < lab.map.size(); ++z) {
        const double f = lab.map.zones[z].area_m2 / lab.map.total_area_m2();
        const double qz = dp_kpa / lab.rea[z];
        ps += f * manikind::physics::saturation_vapour_pressure_iapws_pa(35.0 - qz * 0.01) / 1000.0;
        q += f * qz;
    }
    const double p_air = 0.4 * manikind::physics::saturation_vapour_pressure_iapws_pa(35.0) / 1000.0;
    CHECK(nude.evaporative_total_parallel->value == Approx((ps - p_air) / q).epsilon(1e-9));
    CHECK(nude.evaporative_total_parallel->value < ensemble(at_sensor, "nude").evaporative_total_parallel->value);
    CHECK_THAT(cl::to_json(at_surface)["method"]["evaporative"].get<std::string>(), Catch::Contains("wet fabric's surface"));
    CHECK_THAT(cl::to_json(at_sensor)["method"]["evaporative"].get<std::string>(), Catch::Contains("Ret may read high"));
}
