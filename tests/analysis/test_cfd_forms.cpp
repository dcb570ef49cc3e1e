// Eq. 7 (h0, B, gamma free) and the Eq. S8 shape (a, gamma free) fitted to the paper's CFD
// whole-body coefficients (Tables S8-S10), under three weightings; compared with Eq. 8 and 146.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>

#include "analysis/reconcile/cfd_forms.hpp"
#include "physics/convection.hpp"
#include "physics/paper_cfd_table.hpp"
#include "physics/psychrometrics.hpp"
#include "tests/physics/paper_csv.hpp"

namespace rc = manikind::analysis::reconcile;
namespace ph = manikind::physics;

namespace {

std::vector<rc::CfdHObservation> cfd_table() {
    std::vector<rc::CfdHObservation> obs;
    for (const auto& row : manikind::test::read_paper_csv("cfd_whole_body_cases.csv")) {
        rc::CfdHObservation o;
        o.case_id = std::stoi(row.at("case"));
        o.air_temp_c = manikind::test::num(row, "t_air_c");
        o.air_rh_pct = manikind::test::num(row, "rh_air_pct");
        o.skin_temp_c = o.air_temp_c + manikind::test::num(row, "dt_sk_air_c");
        o.h_w_m2k = manikind::test::num(row, "h_sim_w_m2k");
        obs.push_back(o);
    }
    return obs;
}

// One fit of the 90-case table shared by the test cases (about 0.1 s of fitting).
const rc::CfdGammaReport& report() {
    static const rc::CfdGammaReport rep = [] {
        const auto r = rc::fit_cfd_gamma_forms(cfd_table());
        for (const auto& f : r.fits)
            std::printf("%-40s | %-26s gamma %6.1f +- %5.1f (profile %6.1f..%6.1f) h0 %6.3f +- %5.3f B %5.3f +- %5.3f "
                        "rmse %.3f W/m2K %.1f %% chi2/dof %.2f%s\n",
                        rc::to_string(f.form).c_str(), rc::to_string(f.weighting).c_str(), f.gamma_k_m3_kg,
                        f.gamma_se_k_m3_kg, f.gamma_profile_lo_k_m3_kg, f.gamma_profile_hi_k_m3_kg, f.h0_w_m2k,
                        f.h0_se_w_m2k, f.b_w_m2k, f.b_se_w_m2k, f.rmse_w_m2k, f.rmse_pct, f.chi2_per_dof,
                        f.at_bound ? " [at bound]" : "");
        for (const auto& f : r.eq7_gamma_146)
            std::printf("Eq. 7, gamma = 146 | %-26s h0 %.3f +- %.3f B %.3f +- %.3f rmse %.3f W/m2K %.1f %%\n",
                        rc::to_string(f.weighting).c_str(), f.h0_w_m2k, f.h0_se_w_m2k, f.b_w_m2k, f.b_se_w_m2k,
                        f.rmse_w_m2k, f.rmse_pct);
        std::printf("combined gamma %.1f +- %.1f (within %.1f, between %.1f; range %.1f..%.1f); theory table mean %.1f; "
                    "beta_C/beta_T mean %.1f; z vs 146 %.2f\n",
                    r.gamma_combined_k_m3_kg, r.gamma_u_combined_k_m3_kg, r.gamma_u_within_k_m3_kg,
                    r.gamma_u_between_k_m3_kg, r.gamma_min_k_m3_kg, r.gamma_max_k_m3_kg,
                    r.gamma_theory_table_mean_k_m3_kg, r.gamma_density_neutral_table_mean_k_m3_kg, r.z_vs_paper);
        std::printf("%s: rmse %.3f W/m2K %.2f %%; %s: rmse %.3f W/m2K %.2f %%\n", r.eq8.label.c_str(), r.eq8.rmse_w_m2k,
                    r.eq8.rmse_pct, r.eq_s8.label.c_str(), r.eq_s8.rmse_w_m2k, r.eq_s8.rmse_pct);
        return r;
    }();
    return rep;
}

const rc::CfdFormFit& fit(rc::CfdForm form, rc::CfdWeighting w) {
    for (const auto& f : report().fits)
        if (f.form == form && f.weighting == w) return f;
    throw std::logic_error("no such fit");
}

}  // namespace

TEST_CASE("Tables S8-S10: the embedded CFD table and the shipped CSV give the same fit input", "[analysis][cfd]") {
    const auto csv = cfd_table();
    const auto embedded = ph::paper_cfd_cases();
    REQUIRE(csv.size() == 90);
    REQUIRE(embedded.size() == csv.size());
    for (std::size_t i = 0; i < csv.size(); ++i) {
        CHECK(embedded[i].case_id == csv[i].case_id);
        CHECK(embedded[i].h_sim_w_m2k == csv[i].h_w_m2k);
        CHECK(ph::cfd_skin_temp_c == Approx(csv[i].skin_temp_c).margin(1e-9));
    }
}

TEST_CASE("Eq. 8 on Tables S8-S10: the fixed-coefficient RMSE is the paper's 13.3 % (Discussion), recomputed", "[analysis][cfd]") {
    const auto& r = report();
    REQUIRE(r.n_points == 90);
    // Independent recomputation with the physics library's Eq. 8.
    double s = 0.0;
    for (const auto& o : cfd_table()) {
        const double c_air = ph::vapour_concentration_kg_m3(ph::vapour_pressure_pa(o.air_temp_c, o.air_rh_pct), o.air_temp_c);
        const double dc = ph::saturation_concentration_kg_m3(o.skin_temp_c) - c_air;
        const double e = (ph::h_eq8_w_m2k(o.skin_temp_c - o.air_temp_c, dc) - o.h_w_m2k) / o.h_w_m2k;
        s += e * e;
    }
    CHECK(r.eq8.rmse_pct == Approx(100.0 * std::sqrt(s / 90.0)).epsilon(1e-9));
    // 90 of the paper's 100 cases are tabulated: 13.5 % here beside the printed 13.3 %.
    CHECK(r.eq8.rmse_pct == Approx(13.3).margin(0.5));
    // Eq. S8 ignores humidity and is worse than Eq. 8 on the same table.
    CHECK(r.eq_s8.rmse_w_m2k > r.eq8.rmse_w_m2k);
}

TEST_CASE("Eq. 7 fitted to Tables S8-S10 with h0, B and gamma free reproduces the table at least as well as Eq. 8", "[analysis][cfd]") {
    const auto& r = report();
    for (const auto w : {rc::CfdWeighting::absolute_5pct, rc::CfdWeighting::equal, rc::CfdWeighting::relative_log}) {
        const auto& f = fit(rc::CfdForm::eq7_quarter, w);
        INFO(rc::to_string(w));
        CHECK(f.converged);
        CHECK_FALSE(f.at_bound);
        // Eq. 8 is a member of this family (h0 = 0.3, B = 1.25, gamma = 146): the optimum can only do better
        // in the fit's own metric; equal weights minimise the absolute RMSE, the others the relative one.
        if (w == rc::CfdWeighting::equal) CHECK(f.rmse_w_m2k <= r.eq8.rmse_w_m2k);
        else CHECK(f.rmse_pct <= r.eq8.rmse_pct);
        // Eq. 7 with gamma fixed at 146 is also a member: freeing gamma cannot lose in the fit's own chi2.
        for (const auto& g : r.eq7_gamma_146)
            if (g.weighting == w) CHECK(f.chi2 <= g.chi2 * (1.0 + 1e-9));
    }
}

TEST_CASE("Eq. 7 and the Eq. S8 shape fitted to Tables S8-S10: gamma is finite with a positive uncertainty", "[analysis][cfd]") {
    const auto& r = report();
    REQUIRE(r.fits.size() == 6);
    for (const auto& f : r.fits) {
        INFO(rc::to_string(f.form) << " | " << rc::to_string(f.weighting));
        CHECK(std::isfinite(f.gamma_k_m3_kg));
        CHECK(std::isfinite(f.gamma_se_k_m3_kg));
        CHECK(f.gamma_se_k_m3_kg > 0.0);
        CHECK(f.gamma_profile_lo_k_m3_kg <= f.gamma_k_m3_kg);
        CHECK(f.gamma_profile_hi_k_m3_kg >= f.gamma_k_m3_kg);
        CHECK(f.rmse_w_m2k > 0.0);
        // The Jacobian standard error and the Delta-chi2 profile interval tell the same story (within x3).
        const double half_width = 0.5 * (f.gamma_profile_hi_k_m3_kg - f.gamma_profile_lo_k_m3_kg);
        CHECK(half_width > f.gamma_se_k_m3_kg / 3.0);
        CHECK(half_width < f.gamma_se_k_m3_kg * 3.0);
    }
    CHECK(std::isfinite(r.gamma_combined_k_m3_kg));
    CHECK(r.gamma_u_combined_k_m3_kg > 0.0);
    CHECK(r.gamma_u_combined_k_m3_kg >= r.gamma_u_within_k_m3_kg);
    CHECK(r.gamma_u_combined_k_m3_kg >= r.gamma_u_between_k_m3_kg);
    CHECK(r.gamma_min_k_m3_kg <= r.gamma_combined_k_m3_kg);
    CHECK(r.gamma_max_k_m3_kg >= r.gamma_combined_k_m3_kg);
}

TEST_CASE("Eq. 6-7 theory on Tables S8-S10: beta_C alpha/(beta_T D) averages 145.7 +- 3.7 over the cases (Discussion)", "[analysis][cfd]") {
    CHECK(report().gamma_theory_table_mean_k_m3_kg == Approx(145.7).margin(3.7));
}

TEST_CASE("Eq. 7 fitted to Tables S8-S10 asks for gamma near 180, not 146: the table is reproduced within its 5 % with it", "[analysis][cfd]") {
    const auto& r = report();
    for (const auto w : {rc::CfdWeighting::absolute_5pct, rc::CfdWeighting::equal, rc::CfdWeighting::relative_log}) {
        const auto& f = fit(rc::CfdForm::eq7_quarter, w);
        INFO(rc::to_string(w));
        // What the numbers are (printed above): gamma 179-180, h0 ~0.2, B ~1.29, RMSE ~2.2 %.
        CHECK(f.gamma_k_m3_kg > 170.0);
        CHECK(f.gamma_k_m3_kg < 190.0);
        // 146 lies far outside both the Jacobian and the profile interval of every weighting.
        CHECK(f.gamma_profile_lo_k_m3_kg > 146.0 + 20.0);
        CHECK(std::abs(f.gamma_k_m3_kg - 146.0) > 10.0 * f.gamma_se_k_m3_kg);
        // The three-parameter fit leaves a scatter below the CFD's own 5 %: chi2/dof < 1, so no Birge scaling.
        CHECK(f.chi2_per_dof < 1.0);
        CHECK(f.rmse_pct < 5.0);
        CHECK(f.rmse_pct < 0.5 * r.eq8.rmse_pct);
        // h0 and B stay close to the paper's diffusion floor and coefficient (0.27-0.3 and 1.25-1.26).
        CHECK(f.h0_w_m2k > 0.0);
        CHECK(f.h0_w_m2k < 0.4);
        CHECK(f.b_w_m2k == Approx(1.26).margin(0.1));
    }
    // With gamma held at 146 the best h0, B do no better than Eq. 8's rounded values (~13 %).
    for (const auto& g : r.eq7_gamma_146) CHECK(g.rmse_pct > 10.0);
}

TEST_CASE("Eq. S8 shape a|dT + gamma dC|^0.3 fitted to Tables S8-S10: gamma near 190, a worse fit than Eq. 7", "[analysis][cfd]") {
    const auto& r = report();
    for (const auto w : {rc::CfdWeighting::absolute_5pct, rc::CfdWeighting::equal, rc::CfdWeighting::relative_log}) {
        const auto& s8 = fit(rc::CfdForm::s8_power_0_3, w);
        const auto& e7 = fit(rc::CfdForm::eq7_quarter, w);
        INFO(rc::to_string(w));
        CHECK(s8.gamma_k_m3_kg > e7.gamma_k_m3_kg);
        CHECK(s8.gamma_k_m3_kg > 146.0 + 10.0 * s8.gamma_se_k_m3_kg);
        CHECK(s8.rmse_pct > 2.0 * e7.rmse_pct);
        CHECK(s8.rmse_pct < r.eq8.rmse_pct);  // still better than gamma = 146 with the 1/4 law
        CHECK(s8.chi2_per_dof > 1.0);         // misfit beyond 5 %: the Birge scaling applies
    }
    // The combined gamma: the between-form spread dominates the within-fit uncertainty, and 146 is
    // several combined standard uncertainties away.
    CHECK(r.gamma_u_between_k_m3_kg > r.gamma_u_within_k_m3_kg);
    CHECK(r.z_vs_paper > 3.0);
    CHECK(r.gamma_theory_table_mean_k_m3_kg < r.gamma_min_k_m3_kg);
    // Even beta_C/beta_T (density-neutral N = 0, without the alpha/D of Eq. 6) lies between 146 and the fits.
    CHECK(r.gamma_density_neutral_table_mean_k_m3_kg > r.gamma_theory_table_mean_k_m3_kg);
    CHECK(r.gamma_density_neutral_table_mean_k_m3_kg < r.gamma_min_k_m3_kg);
}

TEST_CASE("Eq. 7 fitted to Tables S8-S10 without the near-stagnation cases (h > 1.75 W/m2K, the paper's reduced range) still asks for gamma well above 146", "[analysis][cfd]") {
    std::vector<rc::CfdHObservation> upper;
    for (const auto& o : cfd_table())
        if (o.h_w_m2k > 1.75) upper.push_back(o);
    const auto r = rc::fit_cfd_gamma_forms(upper);
    std::printf("h > 1.75 W/m2K (%d cases): Eq. 8 rmse %.2f %%", r.n_points, r.eq8.rmse_pct);
    for (const auto& f : r.fits)
        std::printf("; %s | %s gamma %.1f +- %.1f rmse %.2f %%", f.form == rc::CfdForm::eq7_quarter ? "Eq. 7" : "S8 shape",
                    rc::to_string(f.weighting).c_str(), f.gamma_k_m3_kg, f.gamma_se_k_m3_kg, f.rmse_pct);
    std::printf("; combined %.1f +- %.1f\n", r.gamma_combined_k_m3_kg, r.gamma_u_combined_k_m3_kg);
    REQUIRE(r.n_points < 90);
    // The paper: Eq. 8's RMSE drops to 3.9 % above 1.75 W/m2K (100 cases; 90 tabulated here).
    CHECK(r.eq8.rmse_pct == Approx(3.9).margin(0.6));
    for (const auto& f : r.fits) {
        if (f.form != rc::CfdForm::eq7_quarter) continue;
        INFO(rc::to_string(f.weighting));
        CHECK(f.rmse_pct <= r.eq8.rmse_pct);
        CHECK(f.gamma_k_m3_kg - 2.0 * f.gamma_se_k_m3_kg > 146.0);
    }
}
