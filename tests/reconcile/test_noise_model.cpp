// The scatter model's estimator (analysis/reconcile/noise_model.*): a converged maximum of the
// likelihood, checked against that likelihood computed here independently (dense covariance,
// Cholesky), not against the estimator's own Woodbury algebra.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

#include <Eigen/Dense>

#include "analysis/reconcile/noise_model.hpp"

namespace rc = manikind::analysis::reconcile;

namespace {

// A design like reconcile's: loadings with an air-like and a wall-like column, a gain column
// (the flux) and an offset column (ones), the last two nearly collinear with the first two, as
// the twin's sensitivities are in the isothermal cases.
rc::ReplicateResiduals design(int cases, int trials, int zones, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    rc::ReplicateResiduals d;
    for (int c = 0; c < cases; ++c) {
        Eigen::MatrixXd j(zones, 5);
        std::vector<double> flux(static_cast<std::size_t>(zones));
        const double level = 20.0 + 60.0 * u(rng);
        for (int z = 0; z < zones; ++z) {
            const double q = level * (0.8 + 0.4 * u(rng));
            flux[static_cast<std::size_t>(z)] = q;
            j(z, 0) = -0.12 * q * (0.3 + 1.4 * u(rng));  // air, W/m² per °C
            j(z, 1) = 1.5 * u(rng);                      // humidity, W/m² per % RH
            j(z, 2) = -0.05 * q * (0.3 + 1.4 * u(rng));  // wall
            j(z, 3) = q;                                 // gain
            j(z, 4) = 1.0;                               // offset
        }
        d.loadings.push_back(j);
        d.abs_flux_w_m2.push_back(flux);
        d.residual_w_m2.emplace_back(static_cast<std::size_t>(trials), std::vector<double>(static_cast<std::size_t>(zones), 0.0));
    }
    d.factor_start_sd = {0.1, 0.5, 0.2, 0.01, 0.3};
    return d;
}

rc::ScatterModel truth_model(int zones, std::vector<double> tau) {
    rc::ScatterModel t;
    t.zone_sd_w_m2.assign(static_cast<std::size_t>(zones), 1.2);
    t.relative_sd = 0.01;
    t.factor_sd = std::move(tau);
    return t;
}

// -2 ln L of the data's Helmert contrasts under diag(v) + J T J', computed densely.
double neg2_loglik(const rc::ReplicateResiduals& d, const rc::ScatterModel& m) {
    double out = 0.0;
    for (std::size_t c = 0; c < d.residual_w_m2.size(); ++c) {
        const Eigen::MatrixXd sigma = m.trial_covariance(d.abs_flux_w_m2[c], d.loadings[c]);
        const Eigen::LLT<Eigen::MatrixXd> llt(sigma);
        const double logdet = 2.0 * llt.matrixL().toDenseMatrix().diagonal().array().log().sum();
        const auto& trials = d.residual_w_m2[c];
        const auto zones = static_cast<Eigen::Index>(trials.front().size());
        Eigen::VectorXd sum = Eigen::Map<const Eigen::VectorXd>(trials[0].data(), zones);
        for (std::size_t k = 1; k < trials.size(); ++k) {
            const Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(trials[k].data(), zones);
            const double kk = static_cast<double>(k);
            const Eigen::VectorXd h = (sum - kk * x) / std::sqrt(kk * (kk + 1.0));
            sum += x;
            out += logdet + h.dot(llt.solve(h));
        }
    }
    return out;
}

// What a failed check prints: the steps taken and the five tau.
std::string describe(const rc::ScatterModel& fit) {
    std::string out = std::to_string(fit.iterations) + " iterations; tau =";
    for (double t : fit.factor_sd) out += " " + std::to_string(t);
    return out;
}

// The estimate of residuals drawn from a truth with these tau (zone sd 1.2, kappa 0.01); it
// must have converged.
rc::ScatterModel converged_fit(const rc::ReplicateResiduals& shape, std::vector<double> tau, std::uint64_t seed) {
    const auto zones = static_cast<int>(shape.residual_w_m2.front().front().size());
    const rc::ScatterModel fit = rc::estimate_scatter(rc::simulate_residuals(shape, truth_model(zones, std::move(tau)), seed));
    CHECK(fit.converged);
    return fit;
}

}  // namespace

TEST_CASE("scatter model: the factors' variances are the likelihood's maximum, zero admitted, and it converges") {
    const int zones = 35;
    const auto shape = design(30, 3, zones, 11);
    // Air and wall scatter per trial, none in humidity, gain or offset: the boundary case where
    // 30 EM iterations left gain and offset near their starting values.
    const auto truth = truth_model(zones, {0.15, 0.0, 0.1, 0.0, 0.0});
    for (std::uint64_t seed : {1u, 2u, 3u}) {
        const auto data = rc::simulate_residuals(shape, truth, seed);
        const rc::ScatterModel fit = rc::estimate_scatter(data);
        INFO("seed " << seed << ", " << describe(fit));
        REQUIRE(fit.estimable);
        CHECK(fit.converged);
        CHECK(fit.iterations < 400);
        const double best = neg2_loglik(data, fit);
        // ... and beats the truth it was drawn from (as a maximum must: here by ~40, about the
        // number of parameters, as chi² says it should).
        CHECK(best < neg2_loglik(data, truth));
        // Given the zones' variances the factors' are maximised exactly: moving any tau² by 2 % of
        // the air's (or away from zero) lowers the likelihood. A variance at zero may only go up.
        for (std::size_t k = 0; k < 5; ++k) {
            const double tau_sq = fit.factor_sd[k] * fit.factor_sd[k];
            const double step = 0.02 * std::max(tau_sq, 1e-4 * std::pow(shape.factor_start_sd[k], 2.0));
            for (double sign : {+1.0, -1.0}) {
                if (tau_sq + sign * step < 0.0) continue;
                rc::ScatterModel moved = fit;
                moved.factor_sd[k] = std::sqrt(tau_sq + sign * step);
                INFO("factor " << k << ", sign " << sign);
                CHECK(neg2_loglik(data, moved) >= best - 1e-6);
            }
        }
        // Capped at 3 steps it has not converged, and says so.
        CHECK_FALSE(rc::estimate_scatter(data, 3).converged);
    }
}

TEST_CASE("scatter model: with enough cases each factor is recovered, off the collinear ridge and at zero") {
    // 30 cases leave the offset, the humidity and the gain columns nearly interchangeable (the
    // fit above beats the truth by trading them); 300 cases separate them.
    const int zones = 35;
    const auto shape = design(300, 3, zones, 12);
    SECTION("air and wall scatter, none in humidity, gain or offset") {
        const rc::ScatterModel fit = converged_fit(shape, {0.15, 0.0, 0.1, 0.0, 0.0}, 5);
        INFO(describe(fit));
        CHECK(fit.factor_sd[0] == Approx(0.15).margin(0.02));
        CHECK(fit.factor_sd[1] < 0.1);
        CHECK(fit.factor_sd[2] == Approx(0.10).margin(0.02));
        CHECK(fit.factor_sd[3] < 0.005);  // the start is 0.01; 30 EM steps left 0.0065
        CHECK(fit.factor_sd[4] < 0.1);    // the start is 0.3
        CHECK(fit.relative_sd == Approx(0.01).margin(0.003));
    }
    SECTION("only an offset per trial, twice its start") {
        const rc::ScatterModel fit = converged_fit(shape, {0.0, 0.0, 0.0, 0.0, 0.6}, 6);
        INFO(describe(fit));
        CHECK(fit.factor_sd[4] == Approx(0.6).margin(0.08));
        CHECK(fit.factor_sd[0] < 0.03);
        CHECK(fit.factor_sd[3] < 0.002);
    }
}

TEST_CASE("scatter model: without replicates nothing is estimable, and shapes that disagree are refused") {
    auto one = design(5, 1, 6, 3);
    CHECK_FALSE(rc::estimate_scatter(one).estimable);
    auto bad = design(5, 3, 6, 3);
    bad.loadings.pop_back();
    CHECK_THROWS_AS(rc::estimate_scatter(bad), std::invalid_argument);
}

TEST_CASE("scatter model: zones that scatter alike pool their sigma0, a zone that scatters more keeps its own") {
    // A campaign's shape (15 cases of 3 trials, 35 zones): each zone alone has 30 dof, its sigma0
    // known to some +-13 %; pooled, the zones know their common sigma0 to about +-2 %.
    const int zones = 35;
    const auto shape = design(15, 3, zones, 21);
    const std::vector<double> tau = {0.05, 0.5, 0.1, 0.0, 0.0};
    SECTION("every zone alike: the prior's dof climb and every zone's sigma0 is the pooled one") {
        for (std::uint64_t seed : {31u, 32u, 33u}) {
            const rc::ScatterModel fit = converged_fit(shape, tau, seed);
            INFO("seed " << seed << ", prior dof " << fit.zone_prior_dof << ", " << describe(fit));
            CHECK(fit.zone_prior_dof >= 80.0);
            const auto [lo, hi] = std::minmax_element(fit.zone_sd_w_m2.begin(), fit.zone_sd_w_m2.end());
            CHECK(*hi / *lo < 1.1);  // at the floor's 10 dof they spread 0.9-1.5 W/m² about 1.2
        }
    }
    SECTION("one zone three times as noisy: the pooling gives way and that zone keeps its scatter") {
        rc::ScatterModel truth = truth_model(zones, tau);
        truth.zone_sd_w_m2[7] = 3.6;
        for (std::uint64_t seed : {34u, 35u, 36u}) {
            const rc::ScatterModel fit = rc::estimate_scatter(rc::simulate_residuals(shape, truth, seed));
            INFO("seed " << seed << ", prior dof " << fit.zone_prior_dof << ", zone 7 " << fit.zone_sd_w_m2[7]);
            CHECK(fit.converged);
            // One zone in 35 pulls the prior down to 14-20 dof (pooled at 320 it would read ~1.3).
            CHECK(fit.zone_prior_dof <= 28.0);
            // Within 25 % of 3.6: the zone's own 30 dof scatter some 13 %, and 20 dof of prior at
            // the mean still pull it down a little (seed 36: 2.74; at the floor's 10 dof, 2.99).
            CHECK(fit.zone_sd_w_m2[7] > 2.7);
        }
    }
    SECTION("two kinds of zone (1.0 and 2.0 W/m²): no more pooling than the floor") {
        rc::ScatterModel truth = truth_model(zones, tau);
        for (int z = 0; z < zones; ++z) truth.zone_sd_w_m2[static_cast<std::size_t>(z)] = z % 2 == 0 ? 1.0 : 2.0;
        const rc::ScatterModel fit = rc::estimate_scatter(rc::simulate_residuals(shape, truth, 37));
        INFO("prior dof " << fit.zone_prior_dof);
        double even = 0.0, odd = 0.0;
        for (int z = 0; z < zones; ++z) (z % 2 == 0 ? even : odd) += fit.zone_sd_w_m2[static_cast<std::size_t>(z)];
        even /= 18.0, odd /= 17.0;
        INFO("quiet zones " << even << ", noisy zones " << odd);
        CHECK(fit.zone_prior_dof == 10.0);
        CHECK(odd > 1.3 * even);
    }
}
