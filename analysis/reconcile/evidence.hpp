#pragma once
// The statistics under reconcile (docs/reconcile.md): generalised least squares against the
// noise model's covariance, single terms profiled on a grid so that thousands of simulated
// campaigns cost matrix products rather than fits, and case-level cross-validation and
// robust intervals (cases are the independent units, not zone points).
#include <cstdint>
#include <functional>
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "analysis/reconcile/candidates.hpp"
#include "analysis/reconcile/covariance_factor.hpp"
#include "analysis/reconcile/forward_model.hpp"

namespace manikind::analysis::reconcile::evidence {

// The points a fit is judged on, whitened by the covariance: chi2 = |L^-1 (y - f)|².
struct Subset {
    std::vector<std::size_t> idx;                       // into model.points()
    CovarianceFactor factor;                             // of the covariance restricted to idx
    std::vector<int> case_ids;
    std::vector<std::vector<Eigen::Index>> case_rows;   // positions in idx, per case
    std::vector<Eigen::LLT<Eigen::MatrixXd>> case_llt;  // each case's own block
    Eigen::VectorXd y;                                   // whitened observations
    Eigen::VectorXd w_base;                              // whitened twin-as-given prediction

    Eigen::VectorXd select(const std::vector<double>& v) const;
    Eigen::VectorXd whiten(const std::vector<double>& v) const;
    double chi2(const std::vector<double>& prediction) const;
    Eigen::Index size() const { return static_cast<Eigen::Index>(idx.size()); }
};
// The covariance restricted to the points idx (rows and columns in that order).
Eigen::MatrixXd restrict_to(const Eigen::MatrixXd& covariance, const std::vector<std::size_t>& idx);

// `shared` (NoiseModel::shared_factor, rows of every point, may be null): the covariance's
// directions shared by all cases, for the structured factor. Throws std::runtime_error when the
// covariance is not positive definite.
Subset make_subset(const ForwardModel& model, const Eigen::MatrixXd& covariance, std::vector<std::size_t> idx,
                   const std::vector<double>& base_prediction, const Eigen::MatrixXd* shared = nullptr);

// One single-parameter candidate evaluated on a uniform grid across its bounds.
struct Grid {
    CandidateTerm term;
    std::vector<double> theta;
    std::vector<std::vector<double>> raw;   // predictions of every point, per grid value
    std::vector<bool> valid;                // false where the physics could not be evaluated
};
Grid make_grid(const ForwardModel& model, const CandidateTerm& term, int steps);

// The single-parameter candidates the model supports (partial wettedness for each region that is
// wet in some case), and their grids (computed on two threads).
// The named terms the model supports, then the hypotheses generated from its inputs and the
// zones' geometry (`generated`: "default", "all" or "none"; candidates.hpp).
std::vector<CandidateTerm> single_library(const ForwardModel& model, const std::string& generated = "default");
std::vector<Grid> make_grids(const ForwardModel& model, const std::vector<CandidateTerm>& library, int steps);

// The grid whitened for one subset.
struct WhitenedGrid {
    const Grid* grid = nullptr;
    Eigen::MatrixXd w;                      // n x G
    Eigen::VectorXd norm2;
};
WhitenedGrid whiten_grid(const Subset& s, const Grid& g);

// Minimum of chi2 over a grid, refined by a parabola through the neighbours.
struct ProfileMin {
    double chi2 = 0.0;
    double theta = 0.0;
    double curvature = 0.0;   // d²chi2/dtheta² from the parabola (0 when not available)
    double grid_chi2 = 0.0;   // at the best grid point itself (the parabola's value is a guess between points)
};
ProfileMin profile_min(const Eigen::Ref<const Eigen::VectorXd>& chi2, const Grid& g);

// Profile-minimum chi2 of each grid for each column of whitened data Y (n x B): K x B.
Eigen::MatrixXd profile_chi2(const std::vector<const WhitenedGrid*>& grids, const Eigen::MatrixXd& y);

// B campaigns simulated around a whitened mean: mean + N(0, I).
Eigen::MatrixXd simulate(const Eigen::VectorXd& mean, int count, std::mt19937_64& rng);

// The null distribution of the family's best evidence (docs/reconcile.md, "The null"): the
// largest chi2 reduction any single term (profiled on its grid) or any linear direction (a
// zone's offset or gain, one parameter each) achieves in campaigns simulated from the twin as
// given. Each batch of campaigns is judged against a covariance drawn by `draw_covariance` (the
// noise model as its own estimate scatters: the whole estimation repeated on simulated
// replicates), while the data come from the fitted noise model; without it, the fitted noise
// model judges (its estimate taken as exact). Computed in a basis of the grids' shifts near the
// twin (columns within kShiftCap of it in whitened units; beyond, a shift cannot beat the noise),
// so a covariance draw costs products with r basis vectors, not with every grid column.
struct FamilyNull {
    std::vector<double> max_evidence;   // one per simulated campaign
    // The same at the grids' points alone, without the parabola between them: the observed
    // counterpart is what the data reach at a point, for the reported p (issue 61).
    std::vector<double> max_evidence_at_points;
    std::vector<double> chi2;           // the twin's chi2 in each (a goodness-of-fit null with the same draws)
    int covariance_draws = 0;           // 0: the plug-in noise model
    int basis_rank = 0;
};
FamilyNull family_null(const Subset& s, const std::vector<WhitenedGrid>& grids, const Eigen::MatrixXd& linear_directions,
                       const std::function<Eigen::MatrixXd(std::uint64_t)>& draw_covariance, int simulations,
                       std::uint64_t seed);

// Whitened local directions over a subset: each zone's offset (1 on its points) and gain (the
// base prediction on its points); `kinds` gives (zone, gain?) per column.
Eigen::MatrixXd local_directions(const ForwardModel& model, const Subset& s, const std::vector<double>& base_prediction,
                                 std::vector<std::pair<int, bool>>* kinds);

// Evidence (chi2 reduction) of each linear direction (whitened columns) on whitened residual r.
Eigen::VectorXd linear_evidence(const Eigen::MatrixXd& directions, const Eigen::VectorXd& r);

// The (1 - alpha) quantile of a sample.
double upper_quantile(std::vector<double> sample, double alpha);

// Case-level analysis of a fitted model (linearised at the fit): leave-one-case-out error and
// the case-clustered sandwich covariance.
struct CaseLevel {
    double loo_score = 0.0;                 // sum over held-out cases of their predictive deviance
    double loo_rmse = 0.0;                  // the observation's unit
    std::vector<double> robust_se;          // sandwich, small-sample corrected C/(C - p)
};
CaseLevel case_level(const ForwardModel& model, const Subset& s, const std::vector<CandidateTerm>& terms,
                     const std::vector<double>& theta);

}  // namespace manikind::analysis::reconcile::evidence
