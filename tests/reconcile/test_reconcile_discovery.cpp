// Discovery beyond the list (issue 61): effects no named candidate describes, made by the test
// generator zone by zone from the baseline's own inputs (synthetic_campaign.hpp, zone_truth), not
// through the twin's input_pattern term that reconcile fits. Each must be described in physics
// words with the truth inside its 95 % interval, or left unexplained; never a wrong named term.
#include <catch2/catch.hpp>

#include <cstdio>
#include <set>
#include <string>

#include <tuple>
#include <vector>

#include "analysis/reconcile/from_analysis.hpp"
#include "analysis/zone_map.hpp"
#include "tests/reconcile/synthetic_campaign.hpp"

using namespace manikind;
namespace rc = manikind::analysis::reconcile;
namespace tw = manikind::physics::twin;

namespace {

// Prints what the tool said (the table in docs/reconcile.md, "Discovery beyond the list").
void print_claim(const rc::Report& rep) {
    if (!rep.explanation) std::printf("no claim\n");
    else {
        std::size_t k = 0;
        for (const auto& t : rep.explanation->terms) {
            std::printf("%s%s = %.4g [%.4g, %.4g]", k ? ", then " : "", t.label().c_str(), rep.explanation->values[k],
                        rep.explanation->interval_lo[k], rep.explanation->interval_hi[k]);
            k += t.parameters.size();
        }
        std::printf("%s\n", rep.explanation_partial ? " (partial)" : "");
    }
    std::printf("  %s\n", rep.statement.c_str());
}

rc::Report discover(const tw::TwinVersion& world, test::SyntheticOptions o, const char* what) {
    const auto model = rc::make_twin_model(test::make_campaign(world, o), tw::TwinVersion{});
    auto rep = rc::reconcile(*model);
    std::printf("%s, %d replicates, seed %u: ", what, o.replicates, o.seed);
    print_claim(rep);
    return rep;
}

// The explanation's term with this label, and whether its interval holds `truth`.
bool holds(const rc::CandidateResult& c, const std::string& label, double truth) {
    std::size_t k = 0;
    for (const auto& t : c.terms) {
        if (t.label() == label) return c.interval_lo.at(k) <= truth && truth <= c.interval_hi.at(k);
        k += t.parameters.size();
    }
    return false;
}

std::set<std::string> labels(const rc::CandidateResult& c) {
    std::set<std::string> out;
    for (const auto& t : c.terms) out.insert(t.label());
    return out;
}

}  // namespace

TEST_CASE("discovery: a vertical air gradient of 1.5 K/m is described as a gradient with the truth in its interval, "
          "at 2 and 3 replicates",
          "[reconcile][discovery][proof]") {
    for (int replicates : {2, 3}) {
        test::SyntheticOptions o;
        o.seed = 31;
        o.replicates = replicates;
        o.air_gradient_k_per_m = 1.5;
        const auto rep = discover(tw::TwinVersion{"world", {}}, o, "air gradient 1.5 K/m");
        INFO(replicates << " replicates: " << rep.statement);
        REQUIRE(rep.explanation.has_value());
        CHECK(labels(*rep.explanation) == std::set<std::string>{"input_pattern:air_temp_c/height"});
        CHECK(holds(*rep.explanation, "input_pattern:air_temp_c/height", 1.5));
        CHECK(rep.statement.find("vertical air-temperature gradient") != std::string::npos);
    }
}

namespace {
// At one replicate the lab's scatter is carried from an earlier 3-replicate campaign of it (--noise-from).
rc::Report discover_at(const tw::TwinVersion& world, test::SyntheticOptions o, const char* what) {
    if (o.replicates > 1) return discover(world, o, what);
    test::SyntheticOptions earlier;
    earlier.seed = o.seed + 100;
    earlier.replicates = 3;
    const auto source = rc::make_twin_model(test::make_campaign(tw::TwinVersion{}, earlier), tw::TwinVersion{});
    const auto model = rc::make_twin_model(test::make_campaign(world, o), tw::TwinVersion{},
                                           rc::carried_noise(*source, rc::Options{}.instruments, "an earlier campaign"));
    auto rep = rc::reconcile(*model);
    std::printf("%s, 1 replicate with --noise-from, seed %u: ", what, o.seed);
    print_claim(rep);
    return rep;
}
}  // namespace

TEST_CASE("discovery: the surfaces in front of the body 3 K warmer than the probed wall are described as radiant "
          "asymmetry at the front with the truth in its interval, at 1 (--noise-from), 2 and 3 replicates",
          "[reconcile][discovery][proof]") {
    for (int replicates : {1, 2, 3}) {
        test::SyntheticOptions o;
        o.seed = 32;
        o.replicates = replicates;
        o.front_wall_offset_c = 3.0;
        const auto rep = discover_at(tw::TwinVersion{"world", {}}, o, "front surfaces 3 K warmer");
        INFO(replicates << " replicates: " << rep.statement);
        REQUIRE(rep.explanation.has_value());
        CHECK(labels(*rep.explanation) == std::set<std::string>{"input_pattern:wall_temp_c/front"});
        CHECK(holds(*rep.explanation, "input_pattern:wall_temp_c/front", 3.0));
        CHECK(rep.statement.find("radiant asymmetry") != std::string::npos);
    }
}

TEST_CASE("discovery: one leg drier (wettedness 0.4 on the left thigh, calf and foot) is answered with wettedness on "
          "the left or not at all, never with another term, at 1 (--noise-from), 2 and 3 replicates",
          "[reconcile][discovery][proof]") {
  for (int replicates : {1, 2, 3}) {
    test::SyntheticOptions o;
    o.seed = 33;
    o.replicates = replicates;
    o.left_leg_wettedness = 0.4;
    const auto rep = discover_at(tw::TwinVersion{"world", {}}, o, "left leg wettedness 0.4");
    INFO(replicates << " replicates: " << rep.statement);
    if (rep.explanation)
        for (const auto& t : rep.explanation->terms) {
            INFO(t.label());
            const bool left_wet = (t.term == "partial_wettedness" && t.region.size() > 2 && t.region.substr(t.region.size() - 2) == "_l") ||
                                  (t.generated() && t.input == "wettedness" && t.pattern == "left");
            CHECK(left_wet);
        }
  }
}

TEST_CASE("discovery: humidity buoyancy (gamma 146) with a 1 K/m gradient is answered humidity buoyancy, then a "
          "vertical gradient, both values in their intervals",
          "[reconcile][discovery][proof]") {
    test::SyntheticOptions o;
    o.seed = 34;
    o.air_gradient_k_per_m = 1.0;
    const tw::TwinVersion world{"world", {{"humidity_buoyancy", {{"gamma", 146.0}}, "", {}}}};
    const auto rep = discover(world, o, "gamma 146 + air gradient 1 K/m");
    INFO(rep.statement);
    REQUIRE(rep.explanation.has_value());
    CHECK(labels(*rep.explanation) == std::set<std::string>{"humidity_buoyancy", "input_pattern:air_temp_c/height"});
    CHECK(holds(*rep.explanation, "humidity_buoyancy", 146.0));
    CHECK(holds(*rep.explanation, "input_pattern:air_temp_c/height", 1.0));
}

TEST_CASE("discovery: 10 null campaigns at 2 replicates, the generated hypotheses in the family: at most 1 claim",
          "[reconcile][discovery][null][proof]") {
    // At 3 replicates the null test of test_reconcile_proof.cpp holds the whole family (named and
    // generated); 2 replicates is where the noise model's estimate is weakest ("Proof").
    int claims = 0;
    for (unsigned seed = 201; seed <= 210; ++seed) {
        test::SyntheticOptions o;
        o.seed = seed;
        o.replicates = 2;
        const auto model = rc::make_twin_model(test::make_campaign(tw::TwinVersion{"world", {}}, o), tw::TwinVersion{});
        const auto rep = rc::reconcile(*model);
        if (rep.explanation) {
            ++claims;
            std::printf("null seed %u, 2 replicates: claimed %s\n", seed, rep.explanation->label.c_str());
        }
    }
    std::printf("null campaigns at 2 replicates: %d claims in 10\n", claims);
    CHECK(claims <= 1);
}

TEST_CASE("discovery: a flux still drifting over the steady window is a finding about the measurement, named by zone "
          "and trial, its points left out of the fit, never a term",
          "[reconcile][discovery]") {
    // Two cases, zone 27 drifting 3.1 W/m² in one replicate of case 5, zone 28 within the limit.
    auto cases = test::make_campaign(tw::TwinVersion{}, [] {
        test::SyntheticOptions o;
        o.replicates = 2;
        return o;
    }());
    cases.resize(6);
    for (auto& t : cases[4].trials) t.flux_drift_w_m2.assign(t.q_w_m2.size(), 0.3);
    cases[4].trials[0].flux_drift_w_m2[26] = 3.1;
    cases[4].trials[1].flux_drift_w_m2[27] = 1.9;
    const auto model = rc::make_twin_model(cases, tw::TwinVersion{});
    const auto findings = model->measurement();
    INFO((findings.empty() ? std::string("none") : findings[0]));
    REQUIRE(findings.size() == 1);
    CHECK(findings[0].find("zone 27 (calf_front_l)") != std::string::npos);
    CHECK(findings[0].find("3.1 W/m²") != std::string::npos);
    CHECK(findings[0].find("case 5; c05-r1") != std::string::npos);
    CHECK(findings[0].find("not physics") != std::string::npos);
    CHECK(findings[0].find("1 point left out") != std::string::npos);
    CHECK(model->points().size() == 6 * 35 - 1);
    for (const auto& p : model->points()) CHECK_FALSE((p.case_id == 5 && p.zone == 27));
    CHECK(rc::reconcile(*model).measurement == findings);
}

TEST_CASE("discovery: lagging flux sensors on the calves (25 min, steady windows judged on skin temperature) are said "
          "to be still settling, their points left out, and no physics term is named, at 1, 2 and 3 replicates",
          "[reconcile][discovery][proof]") {
    for (int replicates : {1, 2, 3}) {
        test::SyntheticOptions o;
        o.seed = 41;
        o.replicates = replicates;
        o.lagged_zones = {27, 28, 29, 30};
        o.sensor_lag_min = 25.0;
        const auto rep = discover(tw::TwinVersion{}, o, "calf flux sensors lagging 25 min");
        INFO(replicates << " replicates: " << rep.statement);
        CHECK_FALSE(rep.explanation.has_value());
        CHECK(rep.anomalies.empty());
        REQUIRE_FALSE(rep.measurement.empty());
        std::string said;
        for (const auto& m : rep.measurement) said += m + "\n";
        INFO(said);
        for (const char* zone : {"27 (calf_front_l)", "28 (calf_back_l)", "29 (calf_front_r)", "30 (calf_back_r)"})
            CHECK(said.find(zone) != std::string::npos);
        CHECK(said.find("not physics") != std::string::npos);
    }
    // The same recordings without the drift measure: the twin fails at the calves (the mismatch
    // is real and located there, though nothing is named), so this test would fail without the screen.
    test::SyntheticOptions o;
    o.seed = 41;
    o.replicates = 3;
    o.lagged_zones = {27, 28, 29, 30};
    o.sensor_lag_min = 25.0;
    o.record_drift = false;
    const auto blind = discover(tw::TwinVersion{}, o, "calf flux sensors lagging 25 min, drift not recorded");
    CHECK(blind.gof_p_before < 0.01);
    REQUIRE_FALSE(blind.located.empty());
    CHECK(blind.located.front().where.find("calf") != std::string::npos);
    CHECK_FALSE(blind.explanation.has_value());
}

namespace {
// A one-replicate campaign of a 1.5 K/m air gradient (seed), the lab's scatter carried from its
// earlier 3-replicate campaign (seed 43) as --noise-from carries it.
rc::Report gradient_at_one_replicate(unsigned seed) {
    test::SyntheticOptions earlier;
    earlier.seed = 43;
    earlier.replicates = 3;
    const auto source = rc::make_twin_model(test::make_campaign(tw::TwinVersion{}, earlier), tw::TwinVersion{});
    const auto carried = rc::carried_noise(*source, rc::Options{}.instruments, "an earlier campaign of the lab");
    test::SyntheticOptions o;
    o.seed = seed;
    o.replicates = 1;
    o.air_gradient_k_per_m = 1.5;
    const auto model = rc::make_twin_model(test::make_campaign(tw::TwinVersion{}, o), tw::TwinVersion{}, carried);
    return rc::reconcile(*model);
}
}  // namespace

TEST_CASE("discovery: at one replicate with the lab's scatter carried from a 3-replicate campaign (--noise-from), a "
          "vertical air gradient of 1.5 K/m is described as a gradient alone, never with a wrong partner, in twelve campaigns",
          "[reconcile][discovery][proof]") {
    // Before the noise model held the twin's even response at the |dT|^(1/4) cusp (issue 61),
    // seeds 44-49 gave: the gradient with an air bias of 0.05 +- 0.006 degC (44, a wrong
    // partner), nothing (46), the gradient with its partners untold (48, 49), the gradient alone
    // (45, 47). The gradient is what the world has; each interval is a 95 % one, so one of twelve
    // may miss 1.5 (none did on 2026-11-30; with the even response centred, 44 did: 1.60 [1.51, 1.68]).
    int held = 0;
    for (unsigned seed = 44; seed <= 55; ++seed) {
        const auto rep = gradient_at_one_replicate(seed);
        std::printf("air gradient 1.5 K/m, 1 replicate, --noise-from, seed %u: ", seed);
        print_claim(rep);
        INFO("seed " << seed << ": " << rep.statement);
        REQUIRE(rep.explanation.has_value());
        CHECK(labels(*rep.explanation) == std::set<std::string>{"input_pattern:air_temp_c/height"});
        // Judged under the twin's noise model, zones the gradient puts on the cusp (the pelvis and
        // buttocks) read as local anomalies beside it in 7 of these 12; judged under the gradient's, none.
        CHECK(rep.anomalies.empty());
        held += holds(*rep.explanation, "input_pattern:air_temp_c/height", 1.5) ? 1 : 0;
    }
    CHECK(held >= 11);
}

TEST_CASE("discovery: air speed growing with height in a world with forced convection is answered forced convection, "
          "then the air faster higher up, each with the truth in its interval, never humidity or wettedness",
          "[reconcile][discovery][proof]") {
    // Before the air's speed by height joined the generated hypotheses the remainder after forced
    // convection was claimed as humidity stratified with height and both feet drier: wrong physics.
    // The world convects by forced convection (Eq. 9, scale 1) at a speed 0.12x the probe's at the
    // feet and 1.5x at the head (0.8 per metre about the probe's 1.1 m); the twin knows neither.
    // At one replicate (--noise-from) the same two terms come; their intervals are judged over
    // twelve campaigns by the hidden test below (one campaign's miss is what 95 % allows).
    for (int replicates : {2, 3}) {
        test::SyntheticOptions o;
        o.seed = 35;
        o.replicates = replicates;
        o.air_speed_growth_per_m = 0.8;
        const tw::TwinVersion world{"world", {{"mixed_convection", {{"scale", 1.0}}, "", {}}}};
        const auto rep = discover_at(world, o, "forced convection, air speed growing 0.8/m with height");
        INFO(replicates << " replicates: " << rep.statement);
        REQUIRE(rep.explanation.has_value());
        CHECK(rep.explanation->terms.front().label() == "mixed_convection");
        for (const auto& t : rep.explanation->terms) {
            INFO(t.label());
            CHECK((t.label() == "mixed_convection" || t.label() == "input_pattern:air_speed_m_s/height"));
        }
        CHECK(holds(*rep.explanation, "mixed_convection", 1.0));
        if (labels(*rep.explanation).count("input_pattern:air_speed_m_s/height"))
            CHECK(holds(*rep.explanation, "input_pattern:air_speed_m_s/height", 0.8));
    }
}

// A measurement, run by hand (hidden: 12 campaigns cost CI some two minutes of CPU):
//   build/bin/test_reconcile "[forced-one-replicate]"
// Before the pair was judged under the noise model with both its terms, seed 35 gave the scale
// 1.026 +- 0.006 and 21 of 24 intervals held, every claim partial, one with a third term (the head's
// wet fraction); after, 24 of 24, no third term, one partial (42) (2026-11-30).
TEST_CASE("discovery: at one replicate (--noise-from), forced convection with the air faster higher up in twelve "
          "campaigns: the two terms, their intervals within the binomial margin of 95 %",
          "[reconcile][discovery][proof][.forced-one-replicate]") {
    const tw::TwinVersion world{"world", {{"mixed_convection", {{"scale", 1.0}}, "", {}}}};
    int both = 0, extra = 0, held = 0, intervals = 0;
    for (unsigned seed = 35; seed <= 46; ++seed) {
        test::SyntheticOptions o;
        o.seed = seed;
        o.replicates = 1;
        o.air_speed_growth_per_m = 0.8;
        const auto rep = discover_at(world, o, "forced convection, air speed growing 0.8/m with height");
        INFO("seed " << seed << ": " << rep.statement);
        REQUIRE(rep.explanation.has_value());
        CHECK(rep.explanation->terms.front().label() == "mixed_convection");
        const auto said = labels(*rep.explanation);
        both += said.count("mixed_convection") && said.count("input_pattern:air_speed_m_s/height") ? 1 : 0;
        extra += said.size() > 2 || (said.size() == 2 && !said.count("input_pattern:air_speed_m_s/height")) ? 1 : 0;
        for (const auto& [label, truth] : {std::pair<std::string, double>{"mixed_convection", 1.0},
                                           std::pair<std::string, double>{"input_pattern:air_speed_m_s/height", 0.8}})
            if (said.count(label)) {
                ++intervals;
                held += holds(*rep.explanation, label, truth) ? 1 : 0;
            }
    }
    std::printf("forced convection at one replicate: both terms in %d of 12, a further term in %d, %d of %d intervals hold\n",
                both, extra, held, intervals);
    CHECK(both >= 11);
    // A third step is judged against its own family-wise null (alpha 1 %): two of twelve would
    // happen with probability 0.6 %.
    CHECK(extra <= 1);
    // Binomial(24, 0.95): 19 or fewer held with probability 0.60 %.
    CHECK(intervals >= 22);
    CHECK(held >= intervals - 4);
}

TEST_CASE("discovery: with every generated hypothesis in the family (--hypotheses all), an air probe reading 0.8 K high "
          "is named air_temp_bias, not a pattern of the air over the body",
          "[reconcile][discovery][proof]") {
    test::SyntheticOptions o;
    o.seed = 36;
    o.replicates = 2;
    const tw::TwinVersion world{"world", {{"air_temp_bias", {{"bias_c", 0.8}}, "", {}}}};
    const auto model = rc::make_twin_model(test::make_campaign(world, o), tw::TwinVersion{});
    rc::Options opt;
    opt.hypotheses = "all";
    const auto rep = rc::reconcile(*model, opt);
    INFO(rep.statement);
    REQUIRE(rep.explanation.has_value());
    CHECK(labels(*rep.explanation) == std::set<std::string>{"air_temp_bias"});
    CHECK(holds(*rep.explanation, "air_temp_bias", 0.8));
    // The uniform air offset is the named term itself: only the named one is offered.
    for (const auto& c : rep.candidates) CHECK(c.label != "input_pattern:air_temp_c/uniform");
}
