#pragma once
// What reconcile judges against (docs/reconcile.md): the observed points, the noise model of
// their case means, and the forward models that predict every point with extra physics terms
// on top of their base (the twin over recorded cases; whole-body h against a correlation).
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

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
    // n x g: the part shared by every case (probes' common calibration, the manikin's offset and
    // gain), covariance - shared_factor shared_factorᵀ being zero between cases; it is the same
    // in every covariance the noise model's resampler draws. Empty: none (or not known).
    Eigen::MatrixXd shared_factor;
    std::vector<int> point_replicates;        // replicates behind each point's mean
    bool from_replicates = false;             // random part estimated from replicate scatter
    std::string carried_from;                 // else carried from this earlier campaign (--noise-from)
    int random_dof = 0;                       // pooled degrees of freedom of that estimate
    // The replicate scatter's own estimate (this campaign's): ECME steps taken and whether -2 ln L
    // settled before the cap; empty when nothing was estimated here (one replicate, carried).
    int scatter_steps = 0;
    std::optional<bool> scatter_converged;
    double relative_sd = 0.0;                 // kappa: scatter proportional to |q| (per trial)
    std::vector<std::pair<std::string, double>> trial_factor_sd;  // shared by one trial's zones (per trial)
    std::map<int, double> zone_sd_w_m2;       // sigma0 per zone (per trial)
    double zone_prior_dof = 0.0;              // the sigma0's pooling prior (0: not estimated here)
    double calibration_offset_u_w_m2 = 0.0;   // shared by every point
    double calibration_gain_u = 0.0;          // relative, shared by every point
    double air_temp_u_c = 0.0, wall_temp_u_c = 0.0;  // probes' Type B (standard)
    double probe_shared_fraction = 0.0;       // of that variance, common to every case; the rest per case
    std::string rh_u_text;                     // per case, e.g. "(1.4 + 0.01 RH)/sqrt(3) %"
    std::vector<std::string> notes;            // e.g. "one replicate per case: ..."
};

// Draws covariances as the noise model's own estimate would scatter (docs/reconcile.md, "The
// null"): replicates simulated from the fitted scatter model, estimated again by the same
// procedure, with the Type B parts (fixed, not estimated) added. Each draw is what a campaign
// whose true noise is the fitted model would have been judged against.
class NoiseResampler {
public:
    virtual ~NoiseResampler() = default;
    // n x n, like NoiseModel::covariance. `replicates` > 0: as if every case had that many
    // replicates (for planning: the estimate's scatter and the case means' random part change).
    virtual Eigen::MatrixXd draw(std::uint64_t seed, int replicates = 0) const = 0;
};

class ForwardModel;

// One calibration error of a drawn lab, for `--power` to say how a limit hangs on it.
struct DrawnCalibrationError {
    std::string channel;        // air_temp_c, air_rh_pct, wall_temp_c, heat_flux_offset, heat_flux_gain
    double in_limits = 0.0;     // the error over its spec's limit (within +-1 for a rectangular spec)
    double limit = 0.0;         // that limit at the first case's reading, in the channel's unit (gain: a fraction)
};

// A campaign of a recorded design as it could come out again, with `truth` concealed and
// `replicates` trials per case, drawn only from what the recorded campaign's own estimates say
// (docs/reconcile.md, "Detection limits"): each case's conditions land anew (the replicates'
// spread), the probes err within their Type B, the manikin's calibration errs, and each trial
// scatters as the fitted scatter model. The estimates are made once, when the simulator is made.
class CampaignSimulator {
public:
    virtual ~CampaignSimulator() = default;
    // `calibration` (optional): the drawn probes' errors common to every case, as the twin terms
    // that would correct them (air_temp_bias at the air probe's error, wall_offset at minus the
    // wall probe's), for judging a claim beside the concealed term (names_concealed).
    // `errors` (optional): every calibration error the lab was drawn with, in units of its limit.
    // A draw's errors depend on its seed alone, not on `truth`: the same lab at every effect tried.
    virtual std::unique_ptr<ForwardModel> draw(const std::vector<physics::twin::Term>& truth, int replicates, std::uint64_t seed,
                                               std::vector<physics::twin::Term>* calibration = nullptr,
                                               std::vector<DrawnCalibrationError>* errors = nullptr) const = 0;
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
    // None where the noise is not estimated from the data (stated uncertainties, one replicate).
    virtual std::unique_ptr<NoiseResampler> noise_resampler(const Instruments&, double /*probe_shared_fraction*/,
                                                            const std::vector<physics::twin::Term>& /*with*/ = {}) const {
        return nullptr;
    }
    // For planning (`--power`): draws campaigns of this design (CampaignSimulator). None where
    // the scatter cannot be estimated (one replicate, or not a model of recorded trials).
    virtual std::unique_ptr<CampaignSimulator> campaign_simulator(const Instruments&, double /*probe_shared_fraction*/) const {
        return nullptr;
    }
    // Findings about the recording itself (fluxes still drifting over the steady window), with the
    // points this left out of the fit: never physics (Report::measurement).
    virtual std::vector<std::string> measurement() const { return {}; }
};

// One replicate's steady-window means: its own recorded conditions and zone fluxes.
struct TrialInput {
    physics::twin::TrialConditions conditions;
    std::vector<double> q_w_m2;                  // per zone, aligned with the case's zones
    std::string id;                              // c03-r2, for what is said about the recording
    // Per zone, how far the flux moved over the steady window (|slope| x window, the steady-state
    // check's measure); empty when unknown. A zone drifting beyond kFluxDriftLimit_w_m2 and
    // kFluxDriftOutlier times its trial's median zone, in any replicate of a case, leaves that
    // case's point out of the fit: a zone still settling says nothing about physics (docs/reconcile.md).
    std::vector<double> flux_drift_w_m2;
};

// The steady-state check's default flux-drift limit (analysis/steady_state.hpp), and how far a
// zone must stand out of its trial's median zone to be its own (ours).
inline constexpr double kFluxDriftLimit_w_m2 = 2.0;
inline constexpr double kFluxDriftOutlier = 3.0;

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
// A lab's noise carried from an earlier campaign with replicates (`--noise-from`): the scatter
// model estimated there (per zone id), used where this campaign cannot estimate its own (one
// replicate per case). Its own estimation uncertainty comes with it (`sampler`).
struct CarriedNoise {
    std::string source;                          // what it was estimated from, for the report
    std::map<int, double> zone_sd_w_m2;          // sigma0 per zone id (per trial)
    double relative_sd = 0.0;                    // kappa
    std::vector<double> factor_sd;               // tau_k: air °C, RH %, wall °C, gain, offset W/m²
    int dof = 0;                                 // replicate degrees of freedom behind it
    // Draws (zone_sd by zone id, kappa, tau) as the source's estimate would scatter.
    std::function<CarriedNoise(std::uint64_t)> redraw;
};
// The scatter model of a twin model estimated from its replicates; throws std::invalid_argument
// when it has none (no case with two replicates).
CarriedNoise carried_noise(const ForwardModel& twin_model, const Instruments& instruments, std::string source);

std::unique_ptr<ForwardModel> make_twin_model(std::vector<CaseInput> cases, physics::twin::TwinVersion base,
                                              std::optional<CarriedNoise> carried = std::nullopt);

// Whole-body h observations (the paper's CFD table) against a temperature-only correlation
// h = a |dT + gamma dC|^n (+ h0); supports humidity_buoyancy and diffusion_floor.
struct HObservation {
    int case_id = 0;
    double air_temp_c = 0.0, air_rh_pct = 0.0, skin_temp_c = 35.0;
    double h_w_m2k = 0.0, expanded_u_w_m2k = 0.0, coverage_k = 2.0;
};
std::unique_ptr<ForwardModel> make_whole_body_h_model(std::vector<HObservation> obs, double a = 1.36,
                                                      double exponent = 0.3);

}  // namespace manikind::analysis::reconcile
