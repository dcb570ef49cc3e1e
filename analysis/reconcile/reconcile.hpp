#pragma once
// Reconcile: where do the twin and the recordings disagree, which physics term explains it,
// and how much better is the fit with it (DESIGN.md, "Reconcile").
//
//   Locate:  z = (Q_exp - Q_sim)/U per point (case x zone); points outside their 95 % CI; which
//            condition variables organise the normalised residuals (|Pearson r| as strength).
//   Explain: fit each candidate term (and pairs) by weighted least squares, rank by BIC and
//            leave-one-case-out error, reject implausible or poorly identified fits.
//   Model:   the winner becomes a new twin version; before/after statistics.
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "analysis/reconcile/candidates.hpp"
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

// Predicts every point with a set of extra terms on top of its base physics.
class ForwardModel {
public:
    virtual ~ForwardModel() = default;
    virtual const std::vector<Point>& points() const = 0;
    virtual std::vector<double> predict(const std::vector<physics::twin::Term>& extra) const = 0;
    virtual bool supports(const std::string& term) const = 0;
    virtual std::string base_name() const = 0;
    virtual std::vector<physics::twin::Term> base_terms() const = 0;
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
    double chi2_per_dof = 0.0;   // with u = U/k
    int outside_ci = 0;          // |Q_exp - Q_sim| > U
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
    std::vector<double> uncertainties;  // standard errors
    double chi2 = 0.0;
    double bic = 0.0;
    double delta_bic = 0.0;      // vs the twin as given
    std::optional<double> loo_rmse;  // leave-one-case-out, computed for improving candidates
    FitStats after;
    bool accepted = false;
    std::string reason;          // why rejected, or "explains the residual"
};

struct RegionComparison {
    std::string region;
    FitStats before;
    FitStats after;
};

struct Report {
    std::string twin_name;
    FitStats before;
    bool consistent_before = false;          // nothing to explain
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
    double min_delta_bic = -10.0;            // "very strong" evidence (Kass & Raftery)
    double max_chi2_per_dof_after = 2.0;     // after-fit must be consistent with the CIs
    bool try_pairs = true;
    std::string new_version_name = "reconciled";
};

Report reconcile(const ForwardModel& model, const Options& options = {});

}  // namespace manikind::analysis::reconcile
