// ISO 5725-2:1994 precision of one level of an inter-laboratory study (analysis/interlab).
// The reference values come from the one-way random-effects ANOVA, computed here from the raw
// results without the T1..T5 sums the implementation uses, and from hand calculation.
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "analysis/interlab.hpp"
#include "analysis/interlab_report.hpp"

namespace an = manikind::analysis;

namespace {

// One-way ANOVA with unequal group sizes: MS_within, MS_between and
// s_L² = (MS_between - MS_within) / n0, n0 = (N - Σ n_i² / N) / (p - 1).
struct Anova {
    double grand_mean;
    double ms_within;
    double ms_between;
    double n0;
    double s_l2() const { return (ms_between - ms_within) / n0; }
};

Anova one_way_anova(const std::vector<an::LabCell>& cells) {
    double total = 0.0, n_total = 0.0, sum_n2 = 0.0;
    for (const auto& c : cells) {
        for (double y : c.results) total += y;
        n_total += static_cast<double>(c.results.size());
        sum_n2 += static_cast<double>(c.results.size() * c.results.size());
    }
    const double grand = total / n_total;  // mean of all results = Σ n_i ȳ_i / Σ n_i
    const double p = static_cast<double>(cells.size());
    double ss_within = 0.0, ss_between = 0.0;
    for (const auto& c : cells) {
        double sum = 0.0;
        for (double y : c.results) sum += y;
        const double cell_mean = sum / static_cast<double>(c.results.size());
        for (double y : c.results) ss_within += (y - cell_mean) * (y - cell_mean);
        ss_between += static_cast<double>(c.results.size()) * (cell_mean - grand) * (cell_mean - grand);
    }
    return {grand, ss_within / (n_total - p), ss_between / (p - 1.0), (n_total - sum_n2 / n_total) / (p - 1.0)};
}

}  // namespace

TEST_CASE("interlab: balanced 3 labs x 3 replicates against hand-computed one-way ANOVA") {
    // Lab A 10, 11, 12 (mean 11, s² 1); lab B 12, 13, 14 (mean 13, s² 1); lab C 14, 16, 18 (mean 16, s² 4).
    // By hand: m = 40/3; MS_within = (2 + 2 + 8) / 6 = 2; MS_between = 3 · (49/9 + 1/9 + 64/9) / 2 = 19;
    // s_L² = (19 - 2) / 3 = 17/3; s_R² = 2 + 17/3 = 23/3.
    const std::vector<an::LabCell> cells{{"A", {10, 11, 12}}, {"B", {12, 13, 14}}, {"C", {14, 16, 18}}};
    const auto e = an::estimate_precision(cells);
    const auto a = one_way_anova(cells);
    REQUIRE(a.ms_within == Approx(2.0));
    REQUIRE(a.ms_between == Approx(19.0));
    REQUIRE(a.n0 == Approx(3.0));

    CHECK(e.labs == 3);
    CHECK(e.grand_mean == Approx(40.0 / 3.0).epsilon(1e-12));
    CHECK(e.grand_mean == Approx(a.grand_mean).epsilon(1e-12));
    CHECK(e.repeatability_sd == Approx(std::sqrt(2.0)).epsilon(1e-12));
    CHECK(e.repeatability_sd == Approx(std::sqrt(a.ms_within)).epsilon(1e-12));
    CHECK(e.between_lab_sd == Approx(std::sqrt(17.0 / 3.0)).epsilon(1e-12));
    CHECK(e.between_lab_sd == Approx(std::sqrt(a.s_l2())).epsilon(1e-12));
    CHECK(e.between_lab_variance_raw == Approx(17.0 / 3.0).epsilon(1e-12));
    CHECK(e.reproducibility_sd == Approx(std::sqrt(23.0 / 3.0)).epsilon(1e-12));
    CHECK(e.repeatability_limit == Approx(2.8 * std::sqrt(2.0)).epsilon(1e-12));
    CHECK(e.reproducibility_limit == Approx(2.8 * std::sqrt(23.0 / 3.0)).epsilon(1e-12));

    // Cell summaries and Mandel's statistics (7.3.1): mean of means 40/3, sd of means
    // sqrt((49 + 1 + 64) / 9 / 2) = sqrt(19/3); mean s² = 2, so k = s_i / sqrt(2).
    REQUIRE(e.cells.size() == 3);
    CHECK(e.cells[0].lab_id == "A");
    CHECK(e.cells[2].n == 3);
    CHECK(e.cells[2].mean == Approx(16.0));
    CHECK(e.cells[2].sd == Approx(2.0));
    const double sd_means = std::sqrt(19.0 / 3.0);
    CHECK(e.cells[0].mandel_h == Approx((11.0 - 40.0 / 3.0) / sd_means).epsilon(1e-12));
    CHECK(e.cells[1].mandel_h == Approx((13.0 - 40.0 / 3.0) / sd_means).epsilon(1e-12));
    CHECK(e.cells[2].mandel_h == Approx((16.0 - 40.0 / 3.0) / sd_means).epsilon(1e-12));
    CHECK(e.cells[0].mandel_k == Approx(1.0 / std::sqrt(2.0)).epsilon(1e-12));
    CHECK(e.cells[2].mandel_k == Approx(2.0 / std::sqrt(2.0)).epsilon(1e-12));

    // Cochran: C = 4 / 6; p = 3, n = 3: 5 % critical 0.871 (Table 4), so the cell is accepted.
    CHECK(e.cochran_c == Approx(4.0 / 6.0).epsilon(1e-12));
    CHECK(e.cochran_n == 3);
    CHECK(e.cochran_critical_5pct == Approx(0.871).margin(5e-4));
    CHECK(e.cochran_outcome.empty());
}

TEST_CASE("interlab: unequal replicates match the ANOVA with n0 = (T3 - T4/T3)/(p - 1)") {
    const std::vector<an::LabCell> cells{{"L1", {20.1, 20.5}},
                                         {"L2", {21.0, 20.6, 21.3}},
                                         {"L3", {19.8, 20.2, 20.0, 20.4}},
                                         {"L4", {20.9, 21.4, 20.7, 21.1, 21.0}}};
    const auto e = an::estimate_precision(cells);
    const auto a = one_way_anova(cells);
    // T3 = 14, T4 = 54: n0 = (14 - 54/14) / 3, not the plain mean replicate count 3.5.
    REQUIRE(a.n0 == Approx((14.0 - 54.0 / 14.0) / 3.0));
    REQUIRE(a.s_l2() > 0.0);
    CHECK(e.grand_mean == Approx(a.grand_mean).epsilon(1e-12));
    CHECK(e.repeatability_sd == Approx(std::sqrt(a.ms_within)).epsilon(1e-12));
    CHECK(e.between_lab_sd == Approx(std::sqrt(a.s_l2())).epsilon(1e-10));
    CHECK(e.reproducibility_sd == Approx(std::sqrt(a.ms_within + a.s_l2())).epsilon(1e-10));
    // No majority n (one cell each of 2, 3, 4, 5): the smallest n, the least severe critical value.
    CHECK(e.cochran_n == 2);
    // Mandel's h centres on the unweighted average of the cell means (7.3.1), not on m̂ = T1/T3.
    const double means[] = {20.3, 62.9 / 3.0, 20.1, 21.02};
    const double centre = (means[0] + means[1] + means[2] + means[3]) / 4.0;
    double ss = 0.0;
    for (double m : means) ss += (m - centre) * (m - centre);
    REQUIRE(std::abs(centre - e.grand_mean) > 1e-3);
    CHECK(e.cells[0].mandel_h == Approx((means[0] - centre) / std::sqrt(ss / 3.0)).epsilon(1e-10));
}

TEST_CASE("interlab: a large common offset does not spoil s_L (no T2 T3 - T1^2 cancellation)") {
    // The balanced example shifted by 1e8: every precision statistic is shift-invariant.
    const double o = 1e8;
    const auto e = an::estimate_precision({{"A", {o + 10, o + 11, o + 12}}, {"B", {o + 12, o + 13, o + 14}},
                                           {"C", {o + 14, o + 16, o + 18}}});
    CHECK(e.repeatability_sd == Approx(std::sqrt(2.0)).epsilon(1e-6));
    CHECK(e.between_lab_sd == Approx(std::sqrt(17.0 / 3.0)).epsilon(1e-6));
}

TEST_CASE("interlab: a negative s_L^2 estimate gives s_L = 0 and s_R = s_r (7.4.5)") {
    // Means 2.0, 2.2, 2.1 scatter far less than the replicates do: MS_between < MS_within.
    const std::vector<an::LabCell> cells{{"A", {1.0, 3.0}}, {"B", {1.5, 2.9}}, {"C", {0.0, 4.2}}};
    const auto a = one_way_anova(cells);
    REQUIRE(a.s_l2() < 0.0);
    const auto e = an::estimate_precision(cells);
    CHECK(e.between_lab_variance_raw == Approx(a.s_l2()).epsilon(1e-12));
    CHECK(e.between_lab_sd == 0.0);
    CHECK(e.repeatability_sd == Approx(std::sqrt(a.ms_within)).epsilon(1e-12));
    CHECK(e.reproducibility_sd == e.repeatability_sd);
    CHECK(e.reproducibility_limit == Approx(2.8 * e.repeatability_sd).epsilon(1e-12));
}

TEST_CASE("interlab: Cochran critical values match the published tables") {
    // 5 %: NMS Chemical and Biological Metrology, "Cochran test" critical values (95 %),
    // http://www.nmschembio.org.uk/GenericArticle.aspx?m=395&amid=5622 (3 decimals).
    CHECK(an::cochran_critical(3, 2, 0.05) == Approx(0.967).margin(5e-4));
    CHECK(an::cochran_critical(4, 2, 0.05) == Approx(0.906).margin(5e-4));
    CHECK(an::cochran_critical(5, 2, 0.05) == Approx(0.841).margin(5e-4));
    CHECK(an::cochran_critical(10, 2, 0.05) == Approx(0.602).margin(5e-4));
    CHECK(an::cochran_critical(2, 3, 0.05) == Approx(0.975).margin(5e-4));
    CHECK(an::cochran_critical(4, 3, 0.05) == Approx(0.768).margin(5e-4));
    CHECK(an::cochran_critical(6, 4, 0.05) == Approx(0.532).margin(5e-4));
    CHECK(an::cochran_critical(8, 5, 0.05) == Approx(0.391).margin(5e-4));
    CHECK(an::cochran_critical(20, 5, 0.05) == Approx(0.192).margin(5e-4));
    // 1 %: Cochran's C upper 0.01 critical values by number of variances and df = n - 1,
    // http://faculty.washington.edu/heagerty/Books/Biostatistics/TABLES/Cochran/ (4 decimals).
    CHECK(an::cochran_critical(2, 3, 0.01) == Approx(0.9950).margin(5e-5));
    CHECK(an::cochran_critical(3, 2, 0.01) == Approx(0.9933).margin(5e-5));
    CHECK(an::cochran_critical(4, 3, 0.01) == Approx(0.8643).margin(5e-5));
    CHECK(an::cochran_critical(10, 2, 0.01) == Approx(0.7175).margin(5e-5));
    CHECK(an::cochran_critical(10, 6, 0.01) == Approx(0.3572).margin(5e-5));
    CHECK(an::cochran_critical(40, 2, 0.01) == Approx(0.2940).margin(5e-5));
    // Outside ISO 5725-2 Table 4 (p 2..40, n 2..6): not computed.
    CHECK(std::isnan(an::cochran_critical(41, 2, 0.05)));
    CHECK(std::isnan(an::cochran_critical(5, 7, 0.05)));
    CHECK(std::isnan(an::cochran_critical(1, 3, 0.05)));
}

TEST_CASE("interlab: Cochran outcome straggler and outlier (7.3.2.2)") {
    // p = 4, n = 3: critical 0.768 (5 %) and 0.8643 (1 %). Three cells with s² = 1 and one with
    // s² = x give C = x / (x + 3): x = 12 -> 0.8 (straggler), x = 27 -> 0.9 (outlier).
    auto cells_with = [](double x) {
        const double a = std::sqrt(x);
        return std::vector<an::LabCell>{{"A", {9, 10, 11}}, {"B", {10, 11, 12}}, {"C", {8, 9, 10}},
                                        {"D", {10 - a, 10, 10 + a}}};
    };
    const auto straggler = an::estimate_precision(cells_with(12.0));
    CHECK(straggler.cochran_c == Approx(0.8).epsilon(1e-12));
    CHECK(straggler.cochran_outcome == "straggler");
    const auto outlier = an::estimate_precision(cells_with(27.0));
    CHECK(outlier.cochran_c == Approx(0.9).epsilon(1e-12));
    CHECK(outlier.cochran_outcome == "outlier");
    CHECK(outlier.cells[3].mandel_k == Approx(std::sqrt(27.0 / 7.5)).epsilon(1e-12));  // mean s² = 30/4

    // n = 7 is beyond Table 4: C is still reported, the outcome is left empty.
    const auto beyond = an::estimate_precision({{"A", {1, 2, 3, 4, 5, 6, 7}}, {"B", {1, 1, 1, 1, 1, 1, 100}}});
    CHECK(beyond.cochran_c > 0.9);
    CHECK(std::isnan(beyond.cochran_critical_5pct));
    CHECK(beyond.cochran_outcome.empty());

    // Every s_i = 0: C, k undefined (NaN), no outcome; s_r = 0 and s_R = s_L.
    const auto exact = an::estimate_precision({{"A", {1, 1}}, {"B", {3, 3}}});
    CHECK(std::isnan(exact.cochran_c));
    CHECK(std::isnan(exact.cells[0].mandel_k));
    CHECK(exact.cochran_outcome.empty());
    CHECK(exact.repeatability_sd == 0.0);
    CHECK(exact.reproducibility_sd == Approx(std::sqrt(2.0)).epsilon(1e-12));  // s_L² = 4 / 2
}

TEST_CASE("interlab: invalid input throws std::invalid_argument") {
    using Catch::Matchers::Contains;
    CHECK_THROWS_AS(an::estimate_precision({}), std::invalid_argument);
    CHECK_THROWS_WITH(an::estimate_precision({{"A", {1, 2, 3}}}), Contains("at least 2 laboratories"));
    CHECK_THROWS_AS(an::estimate_precision({{"A", {1, 2, 3}}, {"B", {4}}}), std::invalid_argument);
    CHECK_THROWS_WITH(an::estimate_precision({{"A", {1, 2, 3}}, {"B", {4}}}), Contains("'B'"));
    CHECK_THROWS_AS(an::estimate_precision({{"A", {1, 2}}, {"B", {}}}), std::invalid_argument);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    CHECK_THROWS_WITH(an::estimate_precision({{"A", {1, nan}}, {"B", {3, 4}}}), Contains("non-finite"));
    CHECK_THROWS_AS(an::estimate_precision({{"A", {1, 2}}, {"B", {3, -inf}}}), std::invalid_argument);
    CHECK_NOTHROW(an::estimate_precision({{"A", {1, 2}}, {"B", {3, 4}}}));
}

namespace {

// A lab's result for one case: the included trials' whole-body fluxes, plus one excluded trial
// that must not count.
manikind::analysis::CaseResult case_with(int id, double skin_c, std::vector<double> fluxes_w_m2) {
    manikind::analysis::CaseResult c;
    c.case_id = id;
    c.skin_setpoint_c = skin_c;
    c.wettedness = 1.0;
    c.n_replicates = static_cast<int>(fluxes_w_m2.size());
    c.type_a_estimable = fluxes_w_m2.size() >= 2;
    double sum = 0.0;
    for (std::size_t i = 0; i < fluxes_w_m2.size(); ++i) {
        manikind::analysis::TrialResult t;
        t.replicate = static_cast<int>(i) + 1;
        t.included = true;
        t.whole_body_q_w_m2 = fluxes_w_m2[i];
        sum += fluxes_w_m2[i];
        c.trials.push_back(t);
    }
    manikind::analysis::TrialResult excluded;
    excluded.included = false;
    excluded.whole_body_q_w_m2 = 999.0;
    c.trials.push_back(excluded);
    c.whole_body.q.value = sum / static_cast<double>(fluxes_w_m2.size());
    c.whole_body.q.U = 3.0;
    return c;
}

}  // namespace

TEST_CASE("interlab report: cases matched by id across labs, a lab with one replicate or another setpoint is left "
          "out of the estimate, with a note",
          "[interlab]") {
    using namespace manikind::analysis;
    LabCampaignResult a{"lab-a", {}}, b{"lab-b", {}}, c{"lab-c", {}};
    a.result.cases = {case_with(1, 35.0, {100, 102, 101}), case_with(2, 35.0, {50, 52}), case_with(3, 35.0, {10, 11})};
    b.result.cases = {case_with(1, 35.0, {110, 111, 112}), case_with(2, 35.0, {60}), case_with(3, 34.0, {12, 13})};
    c.result.cases = {case_with(1, 35.0, {105, 104})};
    const auto report = compare_labs("rr", {a, b, c});
    REQUIRE(report.cases.size() == 3);

    const auto& c1 = report.cases[0];
    REQUIRE(c1.precision);
    CHECK(c1.precision->labs == 3);
    // The excluded trial (999 W/m²) is not a replicate: the same estimate as from the cells alone.
    const auto direct = estimate_precision({{"lab-a", {100, 102, 101}}, {"lab-b", {110, 111, 112}}, {"lab-c", {105, 104}}});
    CHECK(c1.precision->reproducibility_sd == Approx(direct.reproducibility_sd));
    CHECK(c1.precision->grand_mean == Approx(direct.grand_mean));
    CHECK(c1.labs[1].mandel_h == Approx(direct.cells[1].mandel_h));

    const auto& c2 = report.cases[1];  // lab-b has one replicate: listed, but only one cell remains
    CHECK(c2.labs.size() == 2);
    CHECK_FALSE(c2.precision);
    CHECK_THAT(c2.note, Catch::Contains("1 lab(s) with two or more usable replicates"));

    const auto& c3 = report.cases[2];  // another skin setpoint in lab-b: not the same level
    CHECK_FALSE(c3.precision);
    CHECK_THAT(c3.note, Catch::Contains("lab 'lab-b' ran case 3 with another skin setpoint"));

    const auto j = interlab_to_json(report);
    CHECK(j["cases"][0]["precision"]["reproducibility_limit_w_m2"].get<double>() ==
          Approx(2.8 * direct.reproducibility_sd));
    CHECK(j["cases"][1]["precision"].is_null());
    CHECK_THAT(interlab_to_text(report), Catch::Contains("s_R = ") && Catch::Contains("lab-c"));
}
