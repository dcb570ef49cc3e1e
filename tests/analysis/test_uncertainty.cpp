// GUM pipeline on a hand-computed campaign (tests/data/recordings/good-2zone): 3 replicates,
// 2 zones (front 0.1 m², back 0.3 m²), zone fluxes constant within each trial:
//   front: 10, 12, 14 W/m²   back: 20, 21, 25 W/m²
// Heat-flux spec ±(1.0 + 0.03 |q|) W/m², rectangular.
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

const an::CampaignResult& good_result() {
    static const an::CampaignResult r =
        an::analyze_campaign(an::read_campaign(std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/good-2zone"), short_window());
    return r;
}

}  // namespace

TEST_CASE("coverage factor from Student's t matches the tables") {
    CHECK(an::coverage_factor(2.0) == Approx(4.303).margin(5e-4));   // Text S3: 3 replicates
    CHECK(an::coverage_factor(10.0) == Approx(2.228).margin(5e-4));
    CHECK(an::coverage_factor(an::kInfiniteDof) == Approx(1.960).margin(5e-4));
    CHECK(an::coverage_factor(2.0, 0.99) == Approx(9.925).margin(5e-4));
    CHECK_THROWS(an::coverage_factor(2.0, 1.5));
}

TEST_CASE("Welch-Satterthwaite with an infinite-dof Type B") {
    // u_A = 1 (dof 2), u_B = 1: nu = (1 + 1)² / (1/2) = 8.
    CHECK(an::welch_satterthwaite({{1.0, 2.0}, {1.0, an::kInfiniteDof}}) == Approx(8.0));
    // Type B only: infinite.
    CHECK(std::isinf(an::welch_satterthwaite({{0.0, 2.0}, {1.0, an::kInfiniteDof}})));
    // Type A only: its own dof.
    CHECK(an::welch_satterthwaite({{0.7, 2.0}, {0.0, an::kInfiniteDof}}) == Approx(2.0));
}

TEST_CASE("Type A dominant with 3 replicates gives k = 4.303 (Eq. S7)") {
    const auto e = an::combine(5.0, 2.0, 3, 0.0);
    CHECK(e.nu_eff == Approx(2.0));
    CHECK(e.k == Approx(4.302653).epsilon(1e-6));
    CHECK(e.U == Approx(4.302653 * 2.0).epsilon(1e-6));
}

TEST_CASE("instrument specs: rectangular, normal at k = 2, triangular") {
    an::InstrumentSpec s{1.0, 0.03, an::Distribution::rectangular};
    CHECK(s.standard_uncertainty(-20.0) == Approx((1.0 + 0.03 * 20.0) / std::sqrt(3.0)));
    s.distribution = an::Distribution::normal_k2;
    CHECK(s.standard_uncertainty(20.0) == Approx(1.6 / 2.0));
    s.distribution = an::Distribution::triangular;
    CHECK(s.standard_uncertainty(20.0) == Approx(1.6 / std::sqrt(6.0)));
}

TEST_CASE("zone u_A, u_B, u_C, nu_eff, k and U by hand") {
    const auto& r = good_result();
    REQUIRE(r.cases.size() == 1);
    const auto& c = r.cases[0];
    REQUIRE(c.n_replicates == 3);
    REQUIRE(c.zones.size() == 2);

    // Front: mean 12, s = 2, u_A = 2/sqrt(3); u_B = (1 + 0.03 x 12)/sqrt(3).
    const auto& front = c.zones[0].q;
    CHECK(front.value == Approx(12.0));
    CHECK(front.u_a == Approx(2.0 / std::sqrt(3.0)));
    CHECK(front.u_b == Approx(1.36 / std::sqrt(3.0)));
    const double uc_front = std::sqrt(4.0 / 3.0 + 1.36 * 1.36 / 3.0);
    CHECK(front.u_c == Approx(uc_front));
    const double nu_front = std::pow(uc_front, 4) / (std::pow(2.0 / std::sqrt(3.0), 4) / 2.0);
    CHECK(front.nu_eff == Approx(nu_front));
    CHECK(front.k == Approx(an::coverage_factor(nu_front)));
    CHECK(front.k < 4.303);      // Type B adds infinite-dof information
    CHECK(front.k > 1.96);
    CHECK(front.U == Approx(front.k * uc_front));

    // Back: mean 22, deviations -2, -1, 3 -> s² = 14/2 = 7, u_A = sqrt(7/3); u_B = 1.66/sqrt(3).
    const auto& back = c.zones[1].q;
    CHECK(back.value == Approx(22.0));
    CHECK(back.u_a == Approx(std::sqrt(7.0 / 3.0)));
    CHECK(back.u_b == Approx(1.66 / std::sqrt(3.0)));
    CHECK(back.u_c == Approx(std::sqrt(7.0 / 3.0 + 1.66 * 1.66 / 3.0)));
}

TEST_CASE("area weighting to the whole body with correlated Type B, and the budget") {
    const auto& c = good_result().cases[0];
    // Weights 0.1/0.4 = 0.25 and 0.75. Per-trial whole body: 17.5, 18.75, 22.25 -> mean 19.5.
    const auto& wb = c.whole_body.q;
    CHECK(c.whole_body.area_m2 == Approx(0.4));
    CHECK(wb.value == Approx(19.5));
    // Deviations -2, -0.75, 2.75: s² = (4 + 0.5625 + 7.5625)/2 = 6.0625.
    const double u_a = std::sqrt(6.0625 / 3.0);
    CHECK(wb.u_a == Approx(u_a));
    // Correlated sensors: u_B = 0.25 x 1.36/sqrt(3) + 0.75 x 1.66/sqrt(3).
    const double u_b = (0.25 * 1.36 + 0.75 * 1.66) / std::sqrt(3.0);
    CHECK(wb.u_b == Approx(u_b));
    const double u_c = std::sqrt(u_a * u_a + u_b * u_b);
    CHECK(wb.u_c == Approx(u_c));
    const double nu = std::pow(u_c, 4) / (std::pow(u_a, 4) / 2.0);
    CHECK(wb.nu_eff == Approx(nu));
    CHECK(wb.U == Approx(an::coverage_factor(nu) * u_c));

    // Budget: Type A line + one Type B line per region (here one, "torso"); shares sum to 1.
    const auto& budget = c.whole_body.budget;
    REQUIRE(budget.size() == 2);
    CHECK(budget[0].type == 'A');
    CHECK(budget[0].share == Approx(u_a * u_a / (u_c * u_c)));
    CHECK(budget[1].type == 'B');
    CHECK(budget[1].share == Approx(u_b * u_b / (u_c * u_c)));
    CHECK(budget[0].share + budget[1].share == Approx(1.0));

    // The region "torso" holds both zones: same numbers as the whole body.
    REQUIRE(c.regions.size() == 1);
    CHECK(c.regions[0].q.value == Approx(19.5));
    CHECK(c.regions[0].q.U == Approx(wb.U));
    // Its budget splits Type B by zone: 0.25 x 1.36/sqrt(3) x u_B / u_C² for the front.
    REQUIRE(c.regions[0].budget.size() == 3);
    CHECK(c.regions[0].budget[1].share == Approx(0.25 * 1.36 / std::sqrt(3.0) * u_b / (u_c * u_c)));
}

TEST_CASE("uncorrelated Type B combines zone sensors in quadrature") {
    auto o = short_window();
    o.type_b_correlation = an::TypeBCorrelation::uncorrelated;
    const auto r = an::analyze_campaign(
        an::read_campaign(std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/good-2zone"), o);
    const double u_b = std::sqrt(std::pow(0.25 * 1.36, 2) + std::pow(0.75 * 1.66, 2)) / std::sqrt(3.0);
    CHECK(r.cases.at(0).whole_body.q.u_b == Approx(u_b));
    CHECK(r.cases.at(0).whole_body.q.u_b < good_result().cases.at(0).whole_body.q.u_b);
}

TEST_CASE("conditions carry their own Type A and B") {
    const auto& c = good_result().cases[0];
    REQUIRE(c.conditions.size() >= 3);
    CHECK(c.conditions[0].channel == "air_temp_c");
    CHECK(c.conditions[0].e.value == Approx(39.6));
    CHECK(c.conditions[0].e.u_b == Approx(0.2 / std::sqrt(3.0)));  // EE181, Table S2 default
    CHECK(c.conditions[1].e.u_b == Approx((1.4 + 0.01 * 38.3) / std::sqrt(3.0)));
    REQUIRE(c.wettedness.has_value());
    CHECK(*c.wettedness == 1.0);
}

TEST_CASE("JSON output follows the docs/formats.md contract") {
    const auto j = an::to_json(good_result());
    REQUIRE(j["cases"].size() == 1);
    const auto& c = j["cases"][0];
    CHECK(c["case"] == 9);
    CHECK(c["n_replicates"] == 3);
    CHECK(c["conditions"]["air_temp_c"].get<double>() == Approx(39.6));
    CHECK(c["conditions"].contains("air_rh_pct"));
    CHECK(c["conditions"].contains("skin_temp_c"));
    for (const char* key : {"q_w_m2", "u_a", "u_b", "u_c", "k", "U"}) CHECK(c["whole_body"].contains(key));
    CHECK(c["whole_body"]["q_w_m2"].get<double>() == Approx(19.5));
    CHECK(c["regions"][0]["region"] == "torso");
    REQUIRE(c["trials"].size() == 3);
    const auto& t = c["trials"][0];
    CHECK(t["id"] == "c09-r1");
    CHECK(t["steady"] == true);
    CHECK(t["window_start_s"].get<double>() == Approx(10.0));
    CHECK(t["window_end_s"].get<double>() == Approx(30.0));
    CHECK(t["max_skin_fluctuation_c"].get<double>() == Approx(0.01));
}

TEST_CASE("an empty trial is reported and not averaged") {
    const auto r = an::analyze_campaign(
        an::read_campaign(std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/empty-trial"), short_window());
    REQUIRE(r.cases.size() == 1);
    const auto& c = r.cases[0];
    CHECK(c.n_replicates == 2);
    CHECK_FALSE(c.trials[2].included);
    CHECK(c.trials[2].exclusion_reason.find("empty") != std::string::npos);
    CHECK(c.zones[0].q.value == Approx((10.0 + 12.0) / 2.0));
    const auto j = an::to_json(r);
    REQUIRE(j["excluded_trials"].size() == 1);
    CHECK(j["excluded_trials"][0]["id"] == "c09-r3");
}

TEST_CASE("a case whose every trial is excluded is named, with no results") {
    auto o = short_window();
    o.steady.max_skin_fluctuation_c = 0.001;  // the hand-made skin traces wobble by 0.01 °C
    const auto r = an::analyze_campaign(
        an::read_campaign(std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/good-2zone"), o);
    CHECK(r.cases.empty());
    REQUIRE(r.unanalysed_cases.size() == 1);
    CHECK(r.unanalysed_cases[0].case_id == 9);
    CHECK(an::to_json(r)["excluded_trials"].size() == 3);
    // With include_unsteady the same trials are used, and flagged.
    o.include_unsteady = true;
    const auto r2 = an::analyze_campaign(
        an::read_campaign(std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/good-2zone"), o);
    REQUIRE(r2.cases.size() == 1);
    CHECK(r2.cases[0].n_replicates == 3);
    CHECK_FALSE(r2.cases[0].trials[0].steady.steady);
    CHECK_FALSE(r2.cases[0].warnings.empty());
}

TEST_CASE("a partial trial is reported and never averaged, even with include_unsteady") {
    auto campaign = an::make_synthetic_campaign(1, 3);
    auto& d = campaign.trials[2].data;
    const std::size_t keep = 20 * 60 / 5 + 1;  // 20 min of a 30-min window
    auto cut = [&](std::vector<double>& v) { v.resize(keep); };
    cut(d.t_s);
    cut(d.air_temp_c);
    cut(d.air_rh_pct);
    cut(d.air_speed_m_s);
    cut(d.wall_temp_c);
    for (auto& z : d.skin_temp_c) cut(z);
    for (auto& z : d.heat_flux_w_m2) cut(z);
    an::AnalysisOptions o;
    o.include_unsteady = true;
    const auto r = an::analyze_campaign(campaign, o);
    REQUIRE(r.cases.size() == 1);
    CHECK(r.cases[0].n_replicates == 2);
    CHECK_FALSE(r.cases[0].trials[2].included);
    CHECK(r.cases[0].trials[2].exclusion_reason.find("partial") != std::string::npos);
    // The synthetic zone flux of replicate r is -2 + 0.3 zone + 0.4 (r - 2) plus noise:
    // replicates 1 and 2 average to 0.4 x (-0.5) = -0.2 W/m² off the replicate-2 value.
    CHECK(r.cases[0].zones[0].q.value == Approx(-2.0 + 0.3 - 0.2).margin(0.05));
}

TEST_CASE("zone results carry the replicate-mean skin temperature") {
    const auto& c = good_result().cases[0];
    // front: 35.00/35.01 alternating, rows t = 10..30 s -> 35.00, 35.01, 35.00, 35.01, 35.00
    CHECK(c.zones[0].skin_temp_c == Approx((3 * 35.00 + 2 * 35.01) / 5.0));
    CHECK(c.zones[1].skin_temp_c == Approx(35.0));
}
