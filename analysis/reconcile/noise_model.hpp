#pragma once
// The random part of reconcile's noise model, estimated from the replicates (docs/reconcile.md,
// "Noise model"). One trial's zone residuals (against the twin at that trial's own recorded
// conditions) deviate from their case mean as
//     d_z = e_z + sum_k J_zk eta_k,   e_z ~ N(0, sigma0_z² + (kappa q_z)²),   eta_k ~ N(0, tau_k²)
// e is each zone's own scatter (sigma0 per zone, kappa shared); eta are errors one trial shares
// by all its zones (its air temperature, humidity and wall readings, a gain and an offset of
// the manikin on the day), acting through the twin's sensitivities J. Everything is pooled over
// the cases by maximum likelihood (ECME: an EM step for sigma0 and kappa with eta latent, then
// Fisher scoring for tau), on the within-case (Helmert) contrasts, so the case means themselves
// carry no information into the noise.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace manikind::analysis::reconcile {

struct ReplicateResiduals {
    // [case][trial][zone]: q_trial - q_twin(trial conditions), W/m²
    std::vector<std::vector<std::vector<double>>> residual_w_m2;
    // [case][zone]: |twin flux|, the scale of the relative part
    std::vector<std::vector<double>> abs_flux_w_m2;
    // [case]: zones x factors, the twin's response to one unit of each shared factor
    std::vector<Eigen::MatrixXd> loadings;
    std::vector<double> factor_start_sd;   // a first guess per factor (its unit)
};

struct ScatterModel {
    bool estimable = false;          // at least one case with two replicates
    int dof = 0;                     // sum over cases of (n - 1), per zone
    std::vector<double> zone_sd_w_m2;// sigma0_z
    double relative_sd = 0.0;        // kappa
    double zone_prior_dof = 0.0;     // how strongly the sigma0_z pool toward their mean (empirical Bayes)
    std::vector<double> factor_sd;   // tau_k, per trial (zero where the likelihood puts it)
    int iterations = 0;              // outer ECME steps taken
    bool converged = false;          // -2 ln L settled before max_iterations
    double variance(std::size_t zone, double abs_flux_w_m2) const {
        return zone_sd_w_m2[zone] * zone_sd_w_m2[zone] + relative_sd * relative_sd * abs_flux_w_m2 * abs_flux_w_m2;
    }
    // Covariance of one trial's zone deviations in a case: diag(v) + J T J'.
    Eigen::MatrixXd trial_covariance(const std::vector<double>& abs_flux_w_m2, const Eigen::MatrixXd& loadings) const;
};

// The maximum-likelihood estimate (sigma0 with its prior), iterated until -2 ln L settles or
// max_iterations; the factors' variances may be zero (the likelihood's maximum on its boundary).
// factor_start_sd is where the factors start. Throws std::invalid_argument when the shapes disagree.
ScatterModel estimate_scatter(const ReplicateResiduals& data, int max_iterations = 400);

// Residuals of the same shape (cases, trials, zones) drawn from a scatter model: each trial
// d = e + J eta, e ~ N(0, sigma0_z² + (kappa q_z)²), eta ~ N(0, tau²). What the data would have
// been had the model been true; estimated again, it shows how the estimate scatters.
ReplicateResiduals simulate_residuals(const ReplicateResiduals& shape, const ScatterModel& truth, std::uint64_t seed);

}  // namespace manikind::analysis::reconcile
