// The paper's CFD table (Tables S8-S10) as recordings of whole-body h, with the temperature-only
// correlation (Eq. S8) as the twin: reconcile must find humidity-driven buoyancy.
#include <catch2/catch.hpp>

#include <cstdio>

#include "analysis/reconcile/reconcile.hpp"
#include "physics/paper_cfd_table.hpp"
#include "tests/physics/paper_csv.hpp"

namespace rc = manikind::analysis::reconcile;

namespace {

std::vector<rc::HObservation> cfd_observations() {
    std::vector<rc::HObservation> obs;
    for (const auto& row : manikind::test::read_paper_csv("cfd_whole_body_cases.csv")) {
        rc::HObservation o;
        o.case_id = std::stoi(row.at("case"));
        o.air_temp_c = manikind::test::num(row, "t_air_c");
        o.air_rh_pct = manikind::test::num(row, "rh_air_pct");
        o.skin_temp_c = o.air_temp_c + manikind::test::num(row, "dt_sk_air_c");
        o.h_w_m2k = manikind::test::num(row, "h_sim_w_m2k");
        // The CFD's own stability (Methods: quasi-steady within 5 %), as a standard uncertainty.
        o.expanded_u_w_m2k = 2.0 * 0.05 * o.h_w_m2k;
        o.coverage_k = 2.0;
        obs.push_back(o);
    }
    return obs;
}

}  // namespace

TEST_CASE("reconcile: the CFD table against Eq. S8 finds humidity-driven buoyancy (compare Eq. 8's 146)", "[reconcile][cfd]") {
    const auto model = rc::make_whole_body_h_model(cfd_observations(), 1.36, 0.3);
    const auto rep = rc::reconcile(*model);
    CHECK_FALSE(rep.consistent_before);
    REQUIRE_FALSE(rep.candidates.empty());
    const auto& best = rep.candidates.front();
    std::printf("CFD vs Eq. S8: before rmse %.3f chi2/dof %.2f outside %d/%d; best %s", rep.before.rmse,
                rep.before.chi2_per_dof, rep.before.outside_ci, rep.before.n_points, best.label.c_str());
    for (std::size_t i = 0; i < best.values.size(); ++i)
        std::printf(" %s = %.4g +- %.2g", best.parameter_names[i].c_str(), best.values[i], best.uncertainties[i]);
    std::printf("; after rmse %.3f chi2/dof %.2f outside %d; %s\n", best.after.rmse, best.after.chi2_per_dof,
                best.after.outside_ci, best.reason.c_str());
    for (std::size_t c = 1; c < rep.candidates.size() && c < 4; ++c) {
        const auto& r = rep.candidates[c];
        std::printf("  next: %s dBIC %.1f rmse %.3f", r.label.c_str(), r.delta_bic, r.after.rmse);
        for (std::size_t i = 0; i < r.values.size(); ++i) std::printf(" %s = %.4g", r.parameter_names[i].c_str(), r.values[i]);
        std::printf(" | %s\n", r.reason.c_str());
    }
    // Humidity buoyancy is the leading term, alone or with the diffusion floor of Eq. 5/7.
    bool humidity_leads = false;
    for (const auto& t : best.terms) humidity_leads = humidity_leads || t.term == "humidity_buoyancy";
    CHECK(humidity_leads);
    CHECK(best.after.rmse < 0.6 * rep.before.rmse);
    std::size_t g = 0;
    while (g < best.parameter_names.size() && best.parameter_names[g] != "gamma") ++g;
    REQUIRE(g < best.values.size());
    // The coupling the data ask for is of the order of beta_C alpha/(beta_T D) ~ 146 (Eq. 7-8).
    CHECK(best.values[g] > 80.0);
    CHECK(best.values[g] < 220.0);
}
