// Reconcile benchmark (issues 7, 13). Three figures, each from campaigns the project's own
// generator writes through the whole path (trials -> steady windows -> GUM -> reconcile), with
// the lab scatter of sim/campaign/replicate_scatter.hpp:
//   1. time: 15 cases x 3 replicates x 35 zones, the whole library with pairs, the calibration and
//      the null simulations, beside one plain pass (a twin prediction of every point, whitened);
//   2. the false-claim rate over N campaigns with no concealed physics (alpha = 1 %);
//   3. the coverage of the 95 % interval per term over M campaigns each.
// Usage: bench_reconcile [nulls=100] [coverage_runs=30]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <vector>

#include "analysis/analyze.hpp"
#include "analysis/reconcile/evidence.hpp"
#include "analysis/reconcile/from_analysis.hpp"
#include "analysis/reconcile/reconcile.hpp"
#include "cli/simulated_campaign.hpp"

using namespace manikind;
namespace rc = analysis::reconcile;

namespace {

std::unique_ptr<rc::ForwardModel> campaign_model(const physics::twin::TwinVersion& world, std::uint64_t seed) {
    sim::GeneratorOptions g;
    g.seed = seed;
    g.world = world;
    const auto campaign = simulate_campaign("bench", sim::table_s3_cases(), g);
    const auto result = analysis::analyze_campaign(campaign);
    return rc::make_twin_model(rc::case_inputs_from_results(result, campaign.zone_map), {});
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
    using clock = std::chrono::steady_clock;
    const int nulls = argc > 1 ? std::atoi(argv[1]) : 100;
    const int coverage_runs = argc > 2 ? std::atoi(argv[2]) : 30;

    // 1. Time.
    const auto model = campaign_model({"world", {{"humidity_buoyancy", {{"gamma", 146.0}}, "", {}}}}, 42);
    std::vector<std::size_t> idx(model->points().size());
    std::iota(idx.begin(), idx.end(), 0);
    const rc::Options opt;
    const auto noise = model->noise_model(opt.instruments, opt.probe_shared_fraction);
    const auto base = model->predict({});
    const auto subset = rc::evidence::make_subset(*model, noise.covariance, idx, base);
    const int reps = 200;
    auto t0 = clock::now();
    double sink = 0.0;
    for (int i = 0; i < reps; ++i) sink += subset.chi2(model->predict({}));
    const double pass_ms = std::chrono::duration<double, std::milli>(clock::now() - t0).count() / reps;
    std::vector<double> seconds;
    rc::Report report;
    for (int i = 0; i < 3; ++i) {
        t0 = clock::now();
        report = rc::reconcile(*model);
        seconds.push_back(std::chrono::duration<double>(clock::now() - t0).count());
    }
    std::printf("reconcile benchmark: %zu points (15 cases x 3 replicates x 35 zones), %zu candidates incl. pairs\n",
                model->points().size(), report.candidates.size());
    std::printf("  one plain pass: twin prediction of every point + whitening  %8.3f ms\n", pass_ms);
    std::printf("  reconcile (noise model, %d null simulations, library, pairs, rivals), median of 3  %6.2f s "
                "(min %.2f, max %.2f; target <= 5 s)\n",
                opt.null_simulations, median(seconds), *std::min_element(seconds.begin(), seconds.end()),
                *std::max_element(seconds.begin(), seconds.end()));
    std::printf("  found: %s%s\n", report.explanation ? report.explanation->label.c_str() : "nothing", sink == 0.123 ? " " : "");

    // 2. False claims on campaigns with no concealed physics.
    int claims = 0, anomalies = 0;
    for (int i = 0; i < nulls; ++i) {
        const auto m = campaign_model({"world", {}}, 1000 + static_cast<std::uint64_t>(i));
        const auto r = rc::reconcile(*m);
        claims += r.explanation ? 1 : 0;
        anomalies += r.anomalies.empty() ? 0 : 1;
        if (r.explanation) std::printf("  null %d: claimed %s\n", i, r.explanation->label.c_str());
    }
    if (nulls > 0)
        std::printf("false claims: %d of %d null campaigns (%.1f %%; alpha %.0f %%), local anomalies reported in %d\n", claims,
                    nulls, 100.0 * claims / nulls, 100.0 * opt.alpha, anomalies);

    // 3. Coverage of the 95 % interval, per term, at a mid-range value.
    struct Truth {
        const char* term;
        const char* parameter;
        const char* region;
        double value;
    };
    const Truth truths[] = {{"humidity_buoyancy", "gamma", "", 100.0}, {"diffusion_floor", "h0", "", 0.3},
                            {"mixed_convection", "scale", "", 1.0},    {"wall_offset", "delta_c", "", 1.0},
                            {"air_temp_bias", "bias_c", "", 0.4},      {"textile_resistance", "r_m2k_w", "", 0.006},
                            {"partial_wettedness", "fraction", "head", 0.7}};
    for (const auto& t : truths) {
        if (coverage_runs <= 0) break;
        const auto lib = rc::candidate_library({t.region});
        const auto it = std::find_if(lib.begin(), lib.end(), [&](const auto& c) { return c.term == t.term; });
        int covered = 0;
        for (int i = 0; i < coverage_runs; ++i) {
            const auto m = campaign_model({"world", {{t.term, {{t.parameter, t.value}}, t.region, {}}}}, 5000 + static_cast<std::uint64_t>(i));
            const auto r = rc::fit_candidate(*m, {*it});
            covered += r.interval_lo[0] <= t.value && t.value <= r.interval_hi[0] ? 1 : 0;
            if (std::getenv("BENCH_VERBOSE")) std::printf("    %s: %.5g +- %.3g, 95 %% [%.5g, %.5g]\n", t.term, r.values[0], r.uncertainties[0], r.interval_lo[0], r.interval_hi[0]);
        }
        std::printf("coverage of the 95 %% interval, %s %s = %g: %d of %d (%.0f %%)\n", t.term, t.parameter, t.value, covered,
                    coverage_runs, 100.0 * covered / coverage_runs);
    }
    return 0;
}
