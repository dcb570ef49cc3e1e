// Coverage factor choices (GUM default vs the paper's Text S3), Type B degrees of freedom
// (GUM G.4.2) and a case with one replicate, where Type A is not estimable.
// good-2zone (tests/data/recordings): 3 replicates, zone fluxes front 10/12/14, back 20/21/25 W/m²,
// heat-flux spec ±(1.0 + 0.03 |q|) W/m² rectangular.
#include <cmath>
#include <string>

#include <catch2/catch.hpp>

#include "analysis/analyze.hpp"
#include "analysis/recording.hpp"
#include "analysis/synthetic.hpp"
#include "analysis/uncertainty.hpp"
#include "tests/analysis/short_window.hpp"

namespace an = manikind::analysis;

namespace {

using manikind::test::short_window;

an::CampaignResult good(const an::AnalysisOptions& o) {
    return an::analyze_campaign(an::read_campaign(std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/good-2zone"), o);
}

// t_{0.975, 2} from Student's t tables (the paper's 4.303, Text S3).
constexpr double kT975Dof2 = 4.302653;

}  // namespace

TEST_CASE("Text S3: k = 4.303 for 3 replicates with the paper's coverage") {
    auto o = short_window();
    o.coverage = an::Coverage::replicates_t;
    const auto r = good(o);
    REQUIRE(r.cases.size() == 1);
    const auto& c = r.cases[0];
    REQUIRE(c.n_replicates == 3);
    auto check = [](const an::Estimate& e) {
        CHECK(e.k_dof == Approx(2.0));
        CHECK(e.k == Approx(kT975Dof2).epsilon(1e-6));
        CHECK(e.U == Approx(e.k * e.u_c));
    };
    check(c.whole_body.q);
    for (const auto& a : c.regions) check(a.q);
    for (const auto& z : c.zones) check(z.q);
    for (const auto& ce : c.conditions) check(ce.e);
    // nu_eff is still reported (Welch-Satterthwaite) though k does not use it.
    CHECK(c.whole_body.q.nu_eff > 2.0);
    const auto j = an::to_json(r);
    CHECK(j["method"]["coverage"] == "replicates_t");
    CHECK(j["cases"][0]["whole_body"]["k_dof"].get<double>() == Approx(2.0));
}

TEST_CASE("GUM default: Welch-Satterthwaite k is smaller than the paper's 4.303 once Type B counts") {
    const auto gum = good(short_window());
    auto o = short_window();
    o.coverage = an::Coverage::replicates_t;
    const auto paper = good(o);
    const auto& g = gum.cases.at(0).whole_body.q;
    const auto& p = paper.cases.at(0).whole_body.q;
    CHECK(an::to_json(gum)["method"]["coverage"] == "welch_satterthwaite");
    CHECK(g.k_dof == Approx(g.nu_eff));
    CHECK(g.k == Approx(an::coverage_factor(g.nu_eff)));
    CHECK(g.k < p.k);
    CHECK(g.u_c == Approx(p.u_c));  // only k differs
    CHECK(g.U / p.U == Approx(g.k / p.k));
}

TEST_CASE("GUM G.4.1: Type B dominant with 3 replicates gives a large nu_eff and k near 2") {
    // u_A = 0.2 (dof 2), u_B = 1.0 (dof infinite): nu_eff = 1.04² / (0.2⁴ / 2) = 1352.
    const auto gum = an::combine(10.0, 0.2, 3, 1.0);
    CHECK(gum.nu_eff == Approx(1.04 * 1.04 / (0.0016 / 2.0)));
    CHECK(gum.k == Approx(1.962).margin(1e-3));
    an::CoverageOptions paper;
    paper.coverage = an::Coverage::replicates_t;
    const auto p = an::combine(10.0, 0.2, 3, 1.0, paper);
    CHECK(p.k == Approx(kT975Dof2).epsilon(1e-6));  // Text S3, whatever Type B is
    CHECK(p.U / gum.U == Approx(kT975Dof2 / gum.k));
}

TEST_CASE("GUM G.4.2: Type B dof = 0.5 (Δu/u)^-2, 0.25 gives 8") {
    CHECK(an::type_b_dof(0.25) == Approx(8.0));
    CHECK(an::type_b_dof(0.10) == Approx(50.0));
    CHECK(std::isinf(an::type_b_dof(0.0)));
    CHECK_THROWS(an::type_b_dof(-0.1));

    an::CoverageOptions o;
    o.type_b_dof = an::type_b_dof(0.25);
    // Type B only (replicates agree exactly): nu_eff is Type B's 8, k = t_{0.975, 8} = 2.306.
    const auto b_only = an::combine(10.0, 0.0, 3, 1.0, o);
    CHECK(b_only.nu_eff == Approx(8.0));
    CHECK(b_only.k == Approx(2.306).margin(5e-4));
    // u_A = 1 (dof 2), u_B = 1 (dof 8): nu_eff = 2² / (1/2 + 1/8) = 6.4 (GUM G.2b).
    const auto both = an::combine(10.0, 1.0, 3, 1.0, o);
    CHECK(both.nu_eff == Approx(6.4));
    CHECK(both.nu_b == Approx(8.0));
}

TEST_CASE("GUM G.4.2 through the analysis: zone nu_eff and budget dof with Δu/u = 0.25") {
    auto o = short_window();
    o.type_b_relative_uncertainty = 0.25;
    const auto r = good(o);
    const auto& front = r.cases.at(0).zones.at(0).q;
    const double u_a = 2.0 / std::sqrt(3.0), u_b = 1.36 / std::sqrt(3.0);
    const double u_c2 = u_a * u_a + u_b * u_b;
    CHECK(front.nu_eff == Approx(u_c2 * u_c2 / (std::pow(u_a, 4) / 2.0 + std::pow(u_b, 4) / 8.0)));
    CHECK(front.k == Approx(an::coverage_factor(front.nu_eff)));
    // Smaller than with infinite Type B dof: the Type B is itself uncertain.
    CHECK(front.nu_eff < good(short_window()).cases.at(0).zones.at(0).q.nu_eff);
    for (const auto& b : r.cases.at(0).whole_body.budget)
        if (b.type == 'B') CHECK(b.dof == Approx(8.0));
    const auto j = an::to_json(r);
    CHECK(j["method"]["type_b_dof"].get<double>() == Approx(8.0));
    CHECK(j["cases"][0]["whole_body"]["nu_b"].get<double>() == Approx(8.0));
}

TEST_CASE("one replicate: Type A is not estimable (NaN, flagged, warned), never 0") {
    CHECK(std::isnan(an::type_a_of_mean({5.0})));
    const auto r = an::analyze_campaign(an::make_synthetic_campaign(1, 1));
    REQUIRE(r.cases.size() == 1);
    const auto& c = r.cases[0];
    CHECK(c.n_replicates == 1);
    CHECK_FALSE(c.type_a_estimable);
    bool warned = false;
    for (const auto& w : c.warnings) warned = warned || w.find("not estimable") != std::string::npos;
    CHECK(warned);
    auto check = [](const an::Estimate& e) {
        CHECK_FALSE(e.type_a_estimable);
        CHECK(std::isnan(e.u_a));
        CHECK(e.u_b > 0.0);
        CHECK(e.u_c == Approx(e.u_b));  // U covers Type B only
        CHECK(std::isinf(e.nu_eff));
        CHECK(e.k == Approx(1.960).margin(5e-4));
        CHECK(e.U == Approx(e.k * e.u_b));
    };
    check(c.whole_body.q);
    for (const auto& z : c.zones) check(z.q);
    for (const auto& ce : c.conditions) check(ce.e);
    // The budget's Type A line is absent (NaN, no share), not a zero contribution.
    REQUIRE_FALSE(c.whole_body.budget.empty());
    CHECK(c.whole_body.budget[0].type == 'A');
    CHECK(std::isnan(c.whole_body.budget[0].u_w_m2));
    CHECK(c.whole_body.budget[0].share == 0.0);

    const auto j = an::to_json(r)["cases"][0];
    CHECK(j["type_a_estimable"] == false);
    CHECK(j["whole_body"]["u_a"].is_null());
    CHECK(j["whole_body"]["type_a_estimable"] == false);
    CHECK(j["zones"][0]["u_a"].is_null());
    CHECK(j["conditions_uncertainty"]["air_temp_c"]["u_a"].is_null());
    CHECK(j["whole_body"]["budget"][0]["u_w_m2"].is_null());

    const std::string table = an::format_table(r);
    CHECK(table.find("n/a") != std::string::npos);
    CHECK(table.find("not estimable") != std::string::npos);
}

TEST_CASE("one replicate with the paper's coverage: no t(n - 1), k from Type B alone and a warning") {
    an::AnalysisOptions o;
    o.coverage = an::Coverage::replicates_t;
    const auto r = an::analyze_campaign(an::make_synthetic_campaign(1, 1), o);
    const auto& c = r.cases.at(0);
    CHECK(std::isnan(c.whole_body.q.u_a));
    CHECK(c.whole_body.q.k == Approx(1.960).margin(5e-4));
    bool warned = false;
    for (const auto& w : c.warnings) warned = warned || w.find("t(n - 1)") != std::string::npos;
    CHECK(warned);
}

TEST_CASE("trial results carry each zone's skin range and drift in the struct and in JSON") {
    const auto r = an::analyze_campaign(an::make_synthetic_campaign(1, 2));
    const auto& t = r.cases.at(0).trials.at(0);
    REQUIRE(t.steady.zone_skin.size() == 35);
    CHECK(t.steady.worst_skin_drift_zone >= 1);
    for (const auto& z : t.steady.zone_skin) {
        CHECK(z.samples == 361);
        CHECK(z.range_c <= 0.05);
        CHECK(z.u_drift_c_per_30min > 0.0);
    }
    const auto j = an::to_json(r)["cases"][0]["trials"][0]["skin_drift"];
    REQUIRE(j["zones"].size() == 35);
    CHECK(j["zones"][0].contains("drift_c_per_30min"));
    CHECK(j["zones"][0].contains("u_drift_c_per_30min"));
    CHECK(j["zones"][0].contains("range_c"));
    CHECK(j["worst_zone"].get<int>() == t.steady.worst_skin_drift_zone);
}
