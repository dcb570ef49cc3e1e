// Proof of reconcile (issue 7): campaigns whose world has an effect the baseline twin lacks, at
// a parameter value chosen here (not the theoretical one). reconcile() receives only the case
// list (conditions, Q_exp, U, k), never the world's terms.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>

#include "tests/reconcile/synthetic_campaign.hpp"

using namespace manikind;
namespace rc = manikind::analysis::reconcile;
namespace tw = manikind::physics::twin;

namespace {

rc::Report reconcile_world(const tw::TwinVersion& world, unsigned seed = 7) {
    test::SyntheticOptions o;
    o.seed = seed;
    const auto model = rc::make_twin_model(test::make_campaign(world, o), tw::TwinVersion{});
    return rc::reconcile(*model);
}

void check_recovers(const std::string& term, const std::string& region, const std::string& parameter, double truth,
                    const tw::TwinVersion& world) {
    const auto rep = reconcile_world(world);
    INFO("world: " << term << " " << parameter << " = " << truth);
    CHECK_FALSE(rep.consistent_before);
    REQUIRE(rep.explanation.has_value());
    REQUIRE(rep.explanation->terms.size() == 1);
    CHECK(rep.explanation->terms[0].term == term);
    CHECK(rep.explanation->terms[0].region == region);
    REQUIRE(rep.explanation->parameter_names.at(0) == parameter);
    const double value = rep.explanation->values.at(0);
    const double u = rep.explanation->uncertainties.at(0);
    INFO("fitted " << value << " +- " << u);
    std::printf("recovered %s%s%s: %s = %.5g +- %.2g (truth %.5g), chi2/dof %.2f -> %.2f, RMSE %.2f -> %.2f W/m2\n",
                term.c_str(), region.empty() ? "" : ":", region.c_str(), parameter.c_str(), value, u, truth,
                rep.before.chi2_per_dof, rep.after.chi2_per_dof, rep.before.rmse, rep.after.rmse);
    CHECK(std::abs(value - truth) <= 2.0 * u);  // within its expanded (k = 2) uncertainty
    CHECK(u < 0.1 * std::abs(truth));           // and identified, not merely consistent
    // After the fit the twin is consistent with the CIs, and much better than before.
    CHECK(rep.after.chi2_per_dof < 1.5);
    CHECK(rep.after.outside_ci <= 0.05 * rep.after.n_points + 2);
    CHECK(rep.after.rmse < 0.3 * rep.before.rmse);
    CHECK(rep.explanation->loo_rmse.has_value());
    CHECK(*rep.explanation->loo_rmse < rep.before.rmse);
    CHECK_FALSE(rep.statement.empty());
    // The new twin version carries the term with its fitted value.
    REQUIRE(rep.new_version.terms.size() == 1);
    CHECK(rep.new_version.terms[0].name == term);
    CHECK(rep.new_version.terms[0].parameters.at(parameter) == value);
}

tw::TwinVersion world_with(const std::string& term, const std::string& parameter, double value,
                           const std::string& region = "") {
    return {"world", {{term, {{parameter, value}}, region, {}}}};
}

}  // namespace

TEST_CASE("reconcile: hidden humidity buoyancy (gamma = 120, theory 146) is named and recovered", "[reconcile]") {
    check_recovers("humidity_buoyancy", "", "gamma", 120.0, world_with("humidity_buoyancy", "gamma", 120.0));
}

TEST_CASE("reconcile: hidden diffusion floor (h0 = 0.8 W/m2K) is named and recovered", "[reconcile]") {
    check_recovers("diffusion_floor", "", "h0", 0.8, world_with("diffusion_floor", "h0", 0.8));
}

TEST_CASE("reconcile: hidden mixed convection with the recorded air speed (scale 1.3) is named and recovered", "[reconcile]") {
    check_recovers("mixed_convection", "", "scale", 1.3, world_with("mixed_convection", "scale", 1.3));
}

TEST_CASE("reconcile: walls radiating 1.5 C above the recorded wall temperature are found", "[reconcile]") {
    check_recovers("wall_offset", "", "delta_c", 1.5, world_with("wall_offset", "delta_c", 1.5));
}

TEST_CASE("reconcile: an air probe reading 0.6 C high is found", "[reconcile]") {
    check_recovers("air_temp_bias", "", "bias_c", 0.6, world_with("air_temp_bias", "bias_c", 0.6));
}

TEST_CASE("reconcile: a textile skin resistance of 0.012 m2K/W is found (Text S2.4 measured 0.0054)", "[reconcile]") {
    check_recovers("textile_resistance", "", "r_m2k_w", 0.012, world_with("textile_resistance", "r_m2k_w", 0.012));
}

TEST_CASE("reconcile: a head only 30 % wet (clogged pores, Text S3.4) is found and placed on the head", "[reconcile]") {
    check_recovers("partial_wettedness", "head", "fraction", 0.3, world_with("partial_wettedness", "fraction", 0.3, "head"));
}

TEST_CASE("reconcile: no hidden effect, no explanation claimed (no false discovery)", "[reconcile]") {
    for (unsigned seed : {1u, 2u, 3u}) {
        const auto rep = reconcile_world(tw::TwinVersion{"world", {}}, seed);
        INFO("seed " << seed);
        CHECK(rep.consistent_before);
        CHECK_FALSE(rep.explanation.has_value());
        CHECK_THAT(rep.statement, Catch::Contains("no physics is missing"));
        for (const auto& c : rep.candidates) CHECK_FALSE(c.accepted);
    }
}

TEST_CASE("reconcile: a heat leak on zones 5 and 23 (outside the library) is located, no term claimed", "[reconcile]") {
    const tw::TwinVersion world{"world", {{"heat_leak", {{"q_w_m2", 25.0}}, "", {5, 23}}}};
    const auto rep = reconcile_world(world);
    CHECK_FALSE(rep.consistent_before);
    CHECK_FALSE(rep.explanation.has_value());
    REQUIRE_FALSE(rep.located.empty());
    CHECK_THAT(rep.located[0].where, Catch::Contains("zones 5 (abdomen), 23 (thigh_front_l) only"));
    CHECK_THAT(rep.statement, Catch::Contains("No candidate term explains"));
    CHECK(rep.new_version.terms.empty());
    // The best candidates improve chi2 but are refused for leaving the fit outside the CIs.
    CHECK_THAT(rep.candidates.at(0).reason, Catch::Contains("outside the CIs") || Catch::Contains("implausible"));
}

TEST_CASE("reconcile: locate names vapour concentration among the drivers of a missing humidity term", "[reconcile]") {
    const auto rep = reconcile_world(world_with("humidity_buoyancy", "gamma", 120.0));
    bool named = false;
    for (const auto& l : rep.located) named = named || l.driver == "vapour concentration difference";
    CHECK(named);
    CHECK(rep.before.outside_ci > 0.3 * rep.before.n_points);
    // by region: every region with a residual improves
    for (const auto& r : rep.by_region) CHECK(r.after.rmse <= r.before.rmse + 1e-9);
}
