// The air probe's bias, fitted on campaigns from the project's generator (its recordings carry each
// trial's probe error, 0.05 degC, so the twin's |drive|^(1/4) kinks sit where the real air was
// not): chi2(bias) is a row of cusps, and the curvature at a fit that rests in one of them is the
// cusp's, not the data's (docs/reconcile.md, "Intervals").
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdint>

#include "analysis/analyze.hpp"
#include "analysis/reconcile/from_analysis.hpp"
#include "analysis/reconcile/reconcile.hpp"
#include "cli/simulated_campaign.hpp"

using namespace manikind;
namespace rc = analysis::reconcile;

TEST_CASE("reconcile: the air bias's 95 % interval holds the truth where the fit rests in a cusp of chi2, "
          "and stays about as wide as the estimates scatter",
          "[reconcile][coverage][proof]") {
    constexpr double kTruthC = 0.4;
    const auto lib = rc::candidate_library({});
    const auto term = std::find_if(lib.begin(), lib.end(), [](const auto& c) { return c.term == "air_temp_bias"; });
    REQUIRE(term != lib.end());
    // The seeds (5000 + i, bench_reconcile's coverage campaigns) whose interval from the curvature
    // at the minimum missed 0.4 degC: estimates 0.22-0.32, u 0.024-0.040; the estimates' own
    // scatter over the 60 campaigns is 0.064 degC.
    int told = 0;
    for (const std::uint64_t seed : {5004u, 5014u, 5018u, 5019u, 5022u, 5035u, 5036u}) {
        sim::GeneratorOptions g;
        g.seed = seed;
        g.world = {"world", {{"air_temp_bias", {{"bias_c", kTruthC}}, "", {}}}};
        g.replicates = 3;
        const auto campaign = simulate_campaign("intervals", sim::table_s3_cases(), g);
        const auto result = analysis::analyze_campaign(campaign);
        const auto model = rc::make_twin_model(rc::case_inputs_from_results(result, campaign.zone_map), {});
        const auto r = rc::fit_candidate(*model, {*term});
        INFO("seed " << seed << ": " << r.values[0] << " +- " << r.uncertainties[0] << " [" << r.interval_lo[0] << ", "
                     << r.interval_hi[0] << "]");
        CHECK(r.interval_lo[0] <= kTruthC);
        CHECK(kTruthC <= r.interval_hi[0]);
        // Not widened past twice its floor: the probe's Type B, which the recordings cannot tell from
        // a bias (0.085 degC, docs/reconcile.md "Claims" 7; the estimates' own scatter, 0.064, is of
        // labs whose probe is off only trial by trial).
        CHECK(r.uncertainties[0] < 0.17);
        told += r.interval_lo[0] > 0.0 ? 1 : 0;
    }
    // A 0.4 degC bias (below --power's 80 % limit, 0.51-0.56) is still told from none in these seeds,
    // each chosen for a fit resting in a cusp, but one (5035: 0.24 +- 0.13 since the cusp's even
    // response entered the noise model, 2026-11-30).
    CHECK(told >= 6);
}
