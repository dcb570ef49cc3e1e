// Detection limits for planning (docs/reconcile.md, "Detection limits"): the smallest effect of
// each candidate that reconcile names with 80 % power, for this campaign's cases and noise and
// for other numbers of replicates (the random part of the noise scales as 1/replicates; the
// systematic parts do not).
#include <algorithm>
#include <cmath>
#include <functional>
#include <future>
#include <numeric>
#include <optional>
#include <random>
#include <set>

#include <boost/math/distributions/non_central_chi_squared.hpp>

#include "analysis/reconcile/evidence.hpp"
#include "analysis/reconcile/reconcile.hpp"

namespace manikind::analysis::reconcile {
namespace ev = evidence;
namespace {

constexpr int kGridSteps = 120;
constexpr int kPowerSimulations = 400;

// The whitened prediction at a parameter value between grid points (linear interpolation).
Eigen::VectorXd at(const ev::WhitenedGrid& g, double theta) {
    const auto& t = g.grid->theta;
    const double step = t[1] - t[0];
    const double x = std::clamp((theta - t.front()) / step, 0.0, static_cast<double>(t.size() - 1));
    const auto i = std::min(static_cast<Eigen::Index>(x), static_cast<Eigen::Index>(t.size()) - 2);
    const double f = x - static_cast<double>(i);
    return (1.0 - f) * g.w.col(i) + f * g.w.col(i + 1);
}

}  // namespace

PowerReport detection_limits(const ForwardModel& model, const Options& opt, const std::vector<int>& replicates,
                             double power) {
    const auto& pts = model.points();
    PowerReport rep;
    rep.alpha = opt.alpha;
    const NoiseModel noise = model.noise_model(opt.instruments, opt.probe_shared_fraction);
    rep.campaign_replicates = noise.point_replicates.empty() ? 0 : *std::max_element(noise.point_replicates.begin(), noise.point_replicates.end());
    rep.replicates = replicates;
    if (rep.campaign_replicates > 0 &&
        std::find(replicates.begin(), replicates.end(), rep.campaign_replicates) == replicates.end())
        rep.replicates.push_back(rep.campaign_replicates);
    std::sort(rep.replicates.begin(), rep.replicates.end());
    rep.replicates.erase(std::unique(rep.replicates.begin(), rep.replicates.end()), rep.replicates.end());
    const std::unique_ptr<NoiseResampler> resampler = model.noise_resampler(opt.instruments, opt.probe_shared_fraction);
    const auto base = model.predict({});
    const std::vector<CandidateTerm> library = ev::single_library(model);
    const std::vector<ev::Grid> grids = ev::make_grids(model, library, kGridSteps);
    std::vector<std::size_t> idx(pts.size());
    std::iota(idx.begin(), idx.end(), 0);
    std::mt19937_64 rng(opt.seed + 7);
    for (int n : rep.replicates) {
        // The random part of the case means scales as (campaign's replicates) / n.
        Eigen::MatrixXd cov = noise.covariance - noise.random_covariance;
        for (Eigen::Index a = 0; a < cov.rows(); ++a)
            for (Eigen::Index b = 0; b < cov.cols(); ++b)
                cov(a, b) += noise.random_covariance(a, b) * noise.point_replicates[static_cast<std::size_t>(a)] / n;
        const ev::Subset s = ev::make_subset(model, cov, idx, base);
        std::vector<ev::WhitenedGrid> wg(grids.size());
        for (std::size_t k = 0; k < grids.size(); ++k) wg[k] = ev::whiten_grid(s, grids[k]);
        std::vector<const ev::WhitenedGrid*> all;
        for (const auto& g : wg) all.push_back(&g);
        // The claim threshold reconcile would use with n replicates: the family (terms and each
        // zone's offset and gain) under one alpha, the noise model's own estimate re-drawn as it
        // would scatter with n replicates (docs/reconcile.md, "The null").
        const Eigen::MatrixXd local = model.supports("heat_leak") ? ev::local_directions(model, s, base, nullptr) : Eigen::MatrixXd();
        std::function<Eigen::MatrixXd(std::uint64_t)> draw;
        if (resampler) draw = [&](std::uint64_t seed) { return resampler->draw(seed, n); };
        const double threshold =
            ev::upper_quantile(ev::family_null(s, wg, local, draw, opt.null_simulations, opt.seed).max_evidence, opt.alpha);

        for (std::size_t k = 0; k < library.size(); ++k) {
            const auto& p = library[k].parameters[0];
            DetectionLimit d;
            d.label = library[k].label();
            d.parameter = p.name;
            d.unit = p.unit;
            d.null_value = p.null_value;
            d.replicates = n;
            // Walk away from "no effect" toward the side theory (or the upper bound) lies on.
            const double target = p.theory ? *p.theory : (p.null_value < p.hi ? p.hi : p.lo);
            const double far = target >= p.null_value ? p.hi : p.lo;
            // Noncentral chi2_1 approximation of the evidence: the first value with enough power.
            auto approx_power = [&](double theta) {
                const double lambda = (at(wg[k], theta) - s.w_base).squaredNorm();
                return boost::math::cdf(boost::math::complement(boost::math::non_central_chi_squared(1.0, std::max(lambda, 1e-12)), threshold));
            };
            const int steps = 400;
            std::optional<double> first;
            for (int i = 1; i <= steps && !first; ++i) {
                const double theta = p.null_value + (far - p.null_value) * i / steps;
                if (approx_power(theta) >= power) first = theta;
            }
            // Checked by simulation: the right term named (largest evidence, beyond the null).
            auto simulated_power = [&](double theta) {
                const Eigen::MatrixXd sim = ev::simulate(at(wg[k], theta), kPowerSimulations, rng);
                const Eigen::MatrixXd prof = ev::profile_chi2(all, sim);
                int named = 0;
                for (Eigen::Index b = 0; b < sim.cols(); ++b) {
                    Eigen::Index best = 0;
                    prof.col(b).minCoeff(&best);
                    const double evidence = (sim.col(b) - s.w_base).squaredNorm() - prof(best, b);
                    // A zone's offset or gain that explains more would be reported instead.
                    const double local_best = local.cols() > 0 ? ev::linear_evidence(local, sim.col(b) - s.w_base).maxCoeff() : 0.0;
                    named += evidence > threshold && evidence > local_best && static_cast<std::size_t>(best) == k ? 1 : 0;
                }
                return static_cast<double>(named) / kPowerSimulations;
            };
            if (first) {
                double theta = *first, sim_power = simulated_power(theta);
                // Identification can need more than detection: step out until the simulation agrees.
                for (int i = 0; i < 12 && sim_power < power; ++i) {
                    const double next = theta + (theta - p.null_value) * 0.25;
                    if ((far - next) * (far - p.null_value) < 0.0) break;
                    theta = next;
                    sim_power = simulated_power(theta);
                }
                if (sim_power >= power) d.value = theta;
                d.simulated_power = sim_power;
            }
            rep.limits.push_back(std::move(d));
        }
    }
    // Monotone in replicates by construction: a lab with more replicates can always analyse fewer,
    // so a limit reached with n' replicates is reached with any n > n'.
    for (auto& d : rep.limits) {
        for (const auto& e : rep.limits) {
            if (e.label != d.label || e.replicates >= d.replicates || !e.value) continue;
            if (!d.value || std::abs(*e.value - d.null_value) < std::abs(*d.value - d.null_value)) {
                d.value = e.value;
                d.simulated_power = std::max(d.simulated_power, e.simulated_power);
            }
        }
    }
    return rep;
}

}  // namespace manikind::analysis::reconcile
