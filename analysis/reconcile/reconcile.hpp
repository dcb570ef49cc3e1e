#pragma once
// Reconcile: where do the twin and the recordings disagree, which physics term explains it,
// and how much better is the fit with it (DESIGN.md, "Reconcile").
//
//   Noise:   a covariance for the case means taken from the recordings (docs/reconcile.md):
//            replicate scatter pooled per zone across cases, the manikin's calibration gain and
//            offset shared by every point, each case's probe errors shared by its zones.
//   Locate:  z = (Q_exp - Q_sim)/U per point (case x zone); points outside their 95 % CI; which
//            condition variables organise the residuals; zones with a steady offset.
//   Explain: generalised least squares per candidate term; a term is claimed only when its
//            evidence is beyond the null distribution simulated from the noise model
//            (parametric bootstrap), chosen between terms out of sample by case, and
//            distinguishable from the runner-up; intervals that cover.
//   Model:   the winner becomes a new twin version; before/after statistics.
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "analysis/reconcile/candidates.hpp"
#include "analysis/recording.hpp"
#include "physics/twin/twin.hpp"

namespace manikind::analysis::reconcile {

// One observed quantity: a zone (or a whole body) in one case.
struct Point {
    int case_id = 0;
    int zone = 0;                  // 0 for a whole-body point
    std::string zone_name;
    std::string region;
    double q_exp = 0.0;            // W/m² (or W/m²K for h observations)
    double expanded_u = 0.0;       // U, 95 %
    double coverage_k = 2.0;       // U = k u
    std::map<std::string, double> drivers;  // condition variables for locating (dT, dC, RH, ...)
    double standard_u() const { return expanded_u / coverage_k; }
};

// Type B specifications of the instruments (campaign.json `instruments`), by channel.
using Instruments = std::map<std::string, InstrumentSpec>;

// The noise of the observed case means, as a covariance over the points (docs/reconcile.md).
struct NoiseModel {
    Eigen::MatrixXd covariance;               // n x n, W²/m⁴ (or the observation's unit squared)
    Eigen::MatrixXd random_covariance;        // its replicate-scatter part (scales as 1/replicates)
    std::vector<int> point_replicates;        // replicates behind each point's mean
    bool from_replicates = false;             // random part estimated from replicate scatter
    int random_dof = 0;                       // pooled degrees of freedom of that estimate
    double relative_sd = 0.0;                 // kappa: scatter proportional to |q| (per trial)
    std::vector<std::pair<std::string, double>> trial_factor_sd;  // shared by one trial's zones (per trial)
    std::map<int, double> zone_sd_w_m2;       // sigma0 per zone (per trial)
    double calibration_offset_u_w_m2 = 0.0;   // shared by every point
    double calibration_gain_u = 0.0;          // relative, shared by every point
    double air_temp_u_c = 0.0, wall_temp_u_c = 0.0;  // probes' Type B (standard)
    double probe_shared_fraction = 0.0;       // of that variance, common to every case; the rest per case
    std::string rh_u_text;                     // per case, e.g. "(1.4 + 0.01 RH)/sqrt(3) %"
    std::vector<std::string> notes;            // e.g. "one replicate per case: ..."
};

// Predicts every point with a set of extra terms on top of its base physics.
class ForwardModel {
public:
    virtual ~ForwardModel() = default;
    virtual const std::vector<Point>& points() const = 0;
    virtual std::vector<double> predict(const std::vector<physics::twin::Term>& extra) const = 0;
    virtual bool supports(const std::string& term) const = 0;
    virtual std::string base_name() const = 0;
    virtual std::vector<physics::twin::Term> base_terms() const = 0;
    // The covariance of the observations' errors given the instruments' Type B specs, with the
    // sensitivities and flux scale of the base physics plus `with` (a candidate being judged).
    // `probe_shared_fraction`: the part of a probe's Type B variance common to every case.
    virtual NoiseModel noise_model(const Instruments& instruments, double probe_shared_fraction,
                                   const std::vector<physics::twin::Term>& with = {}) const = 0;
};

// One replicate's steady-window means: its own recorded conditions and zone fluxes.
struct TrialInput {
    physics::twin::TrialConditions conditions;
    std::vector<double> q_w_m2;                  // per zone, aligned with the case's zones
};

// The twin over recorded cases: one point per case and zone.
struct CaseInput {
    int case_id = 0;
    physics::twin::TrialConditions conditions;   // steady-window means
    std::vector<double> q_exp_w_m2;              // per zone, aligned with conditions.zones
    std::vector<double> expanded_u_w_m2;
    std::vector<double> coverage_k;
    std::vector<std::string> zone_names;
    std::vector<std::string> sides;              // l, r, c
    std::vector<double> heights_m;
    std::vector<TrialInput> trials;              // the replicates used; empty when unknown
};
std::unique_ptr<ForwardModel> make_twin_model(std::vector<CaseInput> cases, physics::twin::TwinVersion base);

// Whole-body h observations (the paper's CFD table) against a temperature-only correlation
// h = a |dT + gamma dC|^n (+ h0); supports humidity_buoyancy and diffusion_floor.
struct HObservation {
    int case_id = 0;
    double air_temp_c = 0.0, air_rh_pct = 0.0, skin_temp_c = 35.0;
    double h_w_m2k = 0.0, expanded_u_w_m2k = 0.0, coverage_k = 2.0;
};
std::unique_ptr<ForwardModel> make_whole_body_h_model(std::vector<HObservation> obs, double a = 1.36,
                                                      double exponent = 0.3);

struct FitStats {
    double rmse = 0.0;           // of Q_exp - Q_sim, the observation's unit
    double chi2_per_dof = 0.0;   // generalised: r' Sigma^-1 r / (n - p) with the noise model
    int outside_ci = 0;          // |Q_exp - Q_sim| > U (the analysis's 95 % CI)
    int n_points = 0;
};

struct Located {
    std::string where;
    std::string driver;
    double strength = 0.0;       // |Pearson r| of normalised residuals with the driver
};

struct CandidateResult {
    std::string label;           // term or term:region
    std::vector<CandidateTerm> terms;   // one, or two for a pair
    std::vector<std::string> parameter_names;
    std::vector<double> values;
    std::vector<double> uncertainties;  // standard uncertainty: max(model-based, case-robust)
    std::vector<double> interval_lo, interval_hi;  // 95 % (t with cases - p dof)
    double chi2 = 0.0;           // generalised chi2 after the fit
    double evidence = 0.0;       // chi2 reduction against the twin as given (singles: profile on a grid)
    double bic = 0.0;
    double delta_bic = 0.0;      // vs the twin as given, with ln(cases) per parameter
    std::optional<double> loo_score;  // sum over held-out cases of their generalised chi2
    std::optional<double> loo_rmse;   // leave-one-case-out RMSE, the observation's unit
    FitStats after;
    bool accepted = false;
    std::string reason;          // why not claimed, or what it explains
    std::vector<std::string> advice;  // plausibility: unusual values, never a filter
};

// A steady offset on one zone across cases, beyond the noise after a multiple-testing correction.
struct ZoneAnomaly {
    int zone = 0;
    std::string zone_name;
    double offset_w_m2 = 0.0;    // Q_exp - Q_sim, generalised-least-squares estimate
    double u_w_m2 = 0.0;
    double z = 0.0;
    int cases_outside = 0, cases = 0;
};

struct RegionComparison {
    std::string region;
    FitStats before;
    FitStats after;
};

struct Report {
    std::string twin_name;
    FitStats before;
    bool consistent_before = false;          // nothing to explain: no claim, no anomaly, fit within the noise
    double gof_p_before = 1.0;               // P(chi2 >= observed) for the twin as given
    NoiseModel noise;                        // the covariance the fits were judged against
    double null_threshold = 0.0;             // (1 - alpha) quantile of the best single's evidence under the twin
    int null_simulations = 0;
    double alpha = 0.01;
    std::vector<ZoneAnomaly> anomalies;      // zones left out of the physics fit
    std::vector<std::string> ambiguous_with; // terms the winner could not be told apart from
    std::vector<Located> located;
    std::vector<CandidateResult> candidates; // sorted by BIC
    std::optional<CandidateResult> explanation;
    std::string statement;                   // plain language; says so when nothing explains
    FitStats after;
    std::vector<RegionComparison> by_region;
    std::vector<std::pair<int, RegionComparison>> by_case;  // RegionComparison.region empty
    physics::twin::TwinVersion new_version;  // base + winner (equal to base when no winner)
    std::vector<double> predicted_before;
    std::vector<double> predicted_after;
    std::string best_driver;                 // for the residual plot
};

struct Options {
    double alpha = 0.01;                     // false-claim rate by construction (null bootstrap)
    int null_simulations = 2000;             // campaigns simulated under the twin as given
    int selection_simulations = 1000;        // per runner-up, to tell the winner from it
    double max_chi2_per_dof_after = 1.5;     // a claimed term must leave the fit within the noise
    int max_anomalous_zones = 4;             // more than this is not a local anomaly
    bool try_pairs = true;
    std::uint64_t seed = 20261123;           // the simulations are reproducible
    Instruments instruments = default_instrument_specs();
    double probe_shared_fraction = 0.5;      // of a probe's Type B variance, common to every case
    std::string new_version_name = "reconciled";
};

Report reconcile(const ForwardModel& model, const Options& options = {});

// One candidate (a term or a pair) fitted as reconcile fits its winner: generalised least
// squares under the noise model re-estimated with the candidate's physics, case-level intervals.
// For coverage studies and for users who want a term's value whatever the evidence.
CandidateResult fit_candidate(const ForwardModel& model, const std::vector<CandidateTerm>& terms, const Options& options = {});

// Detection limits for planning (`manikin reconcile --power`): per candidate, the smallest
// effect named with 80 % power for this campaign's cases and noise, at several replicate counts.
struct DetectionLimit {
    std::string label;
    std::string parameter, unit;
    double null_value = 0.0;
    int replicates = 0;
    std::optional<double> value;             // none: not reached within the fit bounds
    double simulated_power = 0.0;            // checked by simulation at that value (right term named)
};
struct PowerReport {
    int campaign_replicates = 0;
    double alpha = 0.01;
    std::vector<int> replicates;
    std::vector<DetectionLimit> limits;
};
PowerReport detection_limits(const ForwardModel& model, const Options& options, const std::vector<int>& replicates,
                             double power = 0.8);

}  // namespace manikind::analysis::reconcile
