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
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "analysis/reconcile/candidates.hpp"
#include "analysis/reconcile/forward_model.hpp"
#include "analysis/recording.hpp"
#include "physics/twin/twin.hpp"

namespace manikind::analysis::reconcile {

namespace evidence {
struct Grid;
}

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
    std::optional<double> loo_score;  // sum over held-out cases of their predictive deviance
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
    std::string kind = "offset"; // "offset" (W/m²) or "gain" (the zone's sensor reads (1 + gain) q)
    double value = 0.0, u = 0.0; // of that kind, generalised-least-squares estimate and standard uncertainty
    double offset_w_m2 = 0.0;    // Q_exp - Q_sim for an offset (0 for a gain)
    double u_w_m2 = 0.0;
    double z = 0.0;
    int cases_outside = 0, cases = 0;
};

struct RegionComparison {
    std::string region;
    FitStats before;
    FitStats after;
};

// One step of an explanation claimed in steps (issue 61): the term(s) claimed, the evidence
// against that step's own null, and the fit after it.
struct ExplanationStep {
    std::string label;
    double evidence = 0.0, threshold = 0.0;
    double chi2_after = 0.0;
    double gof_p_after = 1.0;
    bool partial = false;                    // the fit still beyond the noise after this step
};

struct Report {
    std::string twin_name;
    FitStats before;
    bool consistent_before = false;          // nothing to explain: no claim, no anomaly, fit within the noise
    double gof_p_before = 1.0;               // P(chi2 >= observed) for the twin as given
    // One replicate per case and no scatter carried: the noise is each point's own U/k, a lower
    // bound, so no verdict rests on it: no goodness of fit, no locating, no ± on a candidate
    // (issue 61: on 10 nulls the twin "failed" at p <= 0.008 and the mismatch was "located").
    bool noise_lower_bound = false;
    NoiseModel noise;                        // the covariance the fits were judged against
    double null_threshold = 0.0;             // (1 - alpha) quantile of the family's best evidence under the twin
    int null_simulations = 0;
    int covariance_draws = 0;                // noise-model re-estimations behind the null (0: plug-in)
    double family_evidence = 0.0;            // observed best evidence of any term or zone direction
    double null_p = 1.0;                     // share of null campaigns reaching it (uniform on nulls)
    double alpha = 0.01;
    std::vector<ZoneAnomaly> anomalies;      // zones left out of the physics fit
    std::vector<std::string> ambiguous_with; // terms the winner could not be told apart from
    // The winner needs a partner, but the pairs that would name it tie (each holds the winner):
    // the winner is claimed and the partners listed here, none claimed (issue 61).
    std::vector<std::string> untold_partners;
    std::vector<Located> located;
    std::vector<CandidateResult> candidates; // sorted by BIC
    std::optional<CandidateResult> explanation;   // every term claimed, fitted together
    bool explanation_partial = false;        // the fit is still beyond the noise after it
    double gof_p_after = 1.0;                // goodness of fit after the explanation
    std::vector<ExplanationStep> steps;      // in the order claimed
    std::string remainder;                   // what is left, where and with what it correlates
    std::vector<std::string> measurement;    // findings about the recording itself (ForwardModel::measurement), never physics
    std::vector<Located> remainder_located;
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
    int max_anomalous_zones = 4;             // more than this is not a local anomaly
    bool try_pairs = true;
    // Hypotheses generated from the twin's inputs and the zones' geometry beside the named terms
    // (candidates.hpp, generated_hypotheses): "default", "all" (every input x pattern) or "none".
    std::string hypotheses = "default";
    std::uint64_t seed = 20261123;           // the simulations are reproducible
    Instruments instruments = default_instrument_specs();
    double probe_shared_fraction = 0.5;      // of a probe's Type B variance, common to every case
    std::string new_version_name = "reconciled";
    int grid_steps = 120;                    // per single-parameter candidate across its bounds (profile, null)
    // Planning only (`--power`): the family's claim threshold given, computed once for the design
    // and replicates, instead of the bootstrap null of each simulated campaign.
    std::optional<double> null_threshold;
    // Planning only: the candidates' grids for this model (evidence::make_grids over
    // evidence::single_library, grid_steps), made once per drawn lab and shared by every effect and
    // term tried there. A grid holds predictions at the recorded conditions, which a drawn lab's
    // seed fixes whatever effect is concealed, so sharing it changes no answer. Ignored (made
    // anew) when its candidates are not this model's.
    std::shared_ptr<const std::vector<evidence::Grid>> grids;
    // Planning only: the planner wants the verdict alone, names_concealed(report, label,
    // calibration). Where the winning single is another term and no pair reconcile tries could
    // name `label` beside a calibration term, that verdict is "not named" whatever the pairs and
    // intervals say: the report stops there. Otherwise it stops once the claim is settled. Either
    // way it holds the claim (`explanation`) and a short statement, no candidates or statistics.
    struct VerdictFor {
        std::string label;
        std::vector<physics::twin::Term> calibration;
    };
    std::optional<VerdictFor> verdict_for;
};

Report reconcile(const ForwardModel& model, const Options& options = {});

// One candidate (a term or a pair) fitted as reconcile fits its winner: generalised least
// squares under the noise model re-estimated with the candidate's physics, case-level intervals.
// For coverage studies and for users who want a term's value whatever the evidence.
// `also_from`: a further start (one value per parameter), e.g. the values found step by step.
CandidateResult fit_candidate(const ForwardModel& model, const std::vector<CandidateTerm>& terms, const Options& options = {},
                              const std::vector<double>& also_from = {});

// Detection limits for planning (`manikin reconcile --power`): per candidate, the smallest
// effect named with 80 % power for this campaign's design and noise, at several replicate counts.
// Each limit is checked through the whole decision (reconcile itself) on campaigns of this
// design drawn anew with the effect concealed (ForwardModel::campaign_simulator), starting from a fast
// noncentral-chi2 model of the evidence; where the model cannot draw campaigns (no replicate
// scatter), the fast model's own simulation checks it (`method`).
// The planner's verdict on one drawn campaign, and the power check's: the concealed term `label`
// is named, alone or beside calibration terms (the air probe's bias, the wall's offset) whose 95 %
// intervals hold that campaign's own calibration errors (`calibration`, as the twin terms that
// would correct them). Such a pair is a true answer: the physics concealed and the lab's own probe
// error, both found (a lab's probes are off within their specification, and a large effect
// elsewhere can make that visible). A partner not in `calibration`, or whose interval misses
// its value, is a wrong answer.
bool names_concealed(const Report& report, const std::string& label, const std::vector<physics::twin::Term>& calibration);

struct PowerPoint {
    double value = 0.0;                      // the effect concealed
    int named = 0, campaigns = 0;            // simulated campaigns in which reconcile named it (names_concealed)
    int named_alone = 0;                     // of those, named with no partner
    std::vector<char> draw_named;            // per drawn campaign (the same labs at every value tried)
    std::vector<char> draw_alone;            // per drawn campaign: named with no partner
    // Drawn campaigns reconciled at this value; the others' verdicts were implied by the lab's own
    // verdicts at values bracketing it (PowerOptions::every_lab).
    int reconciled = 0;
};
// How a whole-decision limit hangs on one calibration (docs/reconcile.md, "Detection limits"): the
// drawn labs split by how far that calibration erred, within half its limit or beyond.
struct CalibrationSensitivity {
    std::string channel;                     // air_temp_c, air_rh_pct, wall_temp_c, heat_flux_offset, heat_flux_gain
    double limit = 0.0;                      // the spec's limit at the first case's reading (gain: a fraction)
    double rank_correlation = 0.0;           // Spearman: |error| against the number of values tried at which a lab named the term
    double p_value = 1.0;                    // one-sided permutation test of that correlation being below 0
    bool flagged = false;                    // p below 0.05 over the calibrations tested for this term (Bonferroni)
    double value = 0.0;                      // the value the shares below are counted at (the reported one)
    int within_named = 0, within = 0;        // labs whose error lies within half the limit
    int beyond_named = 0, beyond = 0;
    std::optional<double> limit_within;      // the limit read from those labs alone (none: not reached)
    bool limit_within_at_most = false;       // they named the term often enough at the smallest value tried
};
// Where the planner tries once more before reading its power curve: the geometric middle of the
// bracket around `power` (values sorted by distance from `null_value`) when that bracket climbs
// steeply (more than a quarter of the campaigns between its ends, or its upper end named in all);
// none when the bracket is fine enough or there is none (docs/notes/reconcile-history.md, fifth pass).
std::optional<double> coarse_bracket_middle(const std::vector<PowerPoint>& tried, double null_value, double power);
struct DetectionLimit {
    std::string label;
    std::string parameter, unit;
    double null_value = 0.0;
    int replicates = 0;
    std::optional<double> value;             // none: not reached within the fit bounds
    double simulated_power = 0.0;            // fast model: its simulated share at that value; whole decision: 0.8
    int campaigns = 0;                       // whole-decision campaigns behind it, over every value tried (0: fast model)
    std::vector<PowerPoint> tried;           // whole decision: the values tried, nearest "no effect" first
    std::string method;                      // "whole decision" or "fast model"
    std::vector<CalibrationSensitivity> calibration;  // whole decision only
    // With every lab reconciled at every value (PowerOptions::every_lab): the drawn labs that named
    // the term at a value and missed it at a larger one, where the implied verdicts assume none.
    std::optional<int> non_monotone_labs;
};
struct PowerReport {
    int campaign_replicates = 0;
    double alpha = 0.01;
    std::vector<int> replicates;
    std::vector<DetectionLimit> limits;
    // The evidence a claim must exceed at each replicate count: the whole family's (every
    // candidate and each zone's offset and gain) bootstrap null, as reconcile computes it.
    std::map<int, double> claim_threshold;
};
// How far the whole decision has come (PowerOptions::progress), in drawn campaigns reconciled.
struct PowerProgress {
    int campaigns_done = 0;
    // All it is expected to take: the values tried so far, and for each term not yet settled the
    // mean count of values the settled ones took (4 before any has); it grows or shrinks as they do.
    int campaigns_expected = 0;
    int terms_done = 0, terms = 0;           // terms checked by the whole decision: settled, and all
    std::string label;                       // the term of the campaign just reconciled
    int replicates = 0;
};
struct PowerOptions {
    double power = 0.8;
    int campaigns = 40;                      // whole-decision campaigns per value tried (0: fast model only)
    std::vector<std::string> terms;          // plan only these (a term, or term:region); empty: every candidate
    // Threads the drawn campaigns are reconciled on (0: the hardware's). The answer does not depend
    // on it: each campaign's draws come from its own seed and the verdicts are gathered in order.
    int threads = 0;
    // Reconcile every drawn lab at every value tried. Otherwise a lab that named the term at a value
    // is taken to name it at a larger one, and one that missed it at a value to miss it at a smaller
    // one (the same lab, its draws common to every value: a larger concealed effect is more
    // evidence): only the labs no verdict of their own brackets are reconciled there.
    bool every_lab = false;
    // Called after each drawn campaign reconciled (from the thread that did it, one call at a time).
    std::function<void(const PowerProgress&)> progress;
};
// Fills `d.calibration` from the whole decision's per-lab verdicts (`tried[].draw_named`, values
// sorted by distance from "no effect", as detection_limits leaves them) and each drawn lab's
// calibration errors (`labs`, in the same order); leaves it empty when they do not line up or
// there are fewer than 4 labs (docs/reconcile.md, "Detection limits"; checked: docs/notes/reconcile-history.md,
// eleventh pass).
void calibration_sensitivity(DetectionLimit& d, const std::vector<std::vector<DrawnCalibrationError>>& labs, double power,
                             std::uint64_t seed);
PowerReport detection_limits(const ForwardModel& model, const Options& options, const std::vector<int>& replicates,
                             const PowerOptions& power = {});

}  // namespace manikind::analysis::reconcile
