#pragma once
// Bounded weighted least squares (Levenberg-Marquardt with a numerical Jacobian) for the few
// parameters of a physics term. Residuals are already divided by their standard uncertainty.
#include <functional>
#include <vector>

namespace manikind::analysis::reconcile {

struct Bounds {
    double lo = 0.0;
    double hi = 0.0;
};

struct FitResult {
    std::vector<double> parameters;
    std::vector<double> standard_errors;  // from (J'J)^-1, scaled by chi2/dof when that exceeds 1
    double chi2 = 0.0;
    int n_points = 0;
    int iterations = 0;
    bool converged = false;
};

using ResidualFunction = std::function<std::vector<double>(const std::vector<double>&)>;

// Without `with_errors` the standard errors are left empty: a multi-start fit asks for them at its
// best start only (standard_errors_at), not at every start (four residual evaluations each).
FitResult fit_weighted_least_squares(const ResidualFunction& residuals, std::vector<double> start,
                                     const std::vector<Bounds>& bounds, int max_iterations = 60, bool with_errors = true);

// The standard errors a fit ending at `p` (chi2 over n_points residuals) reports.
std::vector<double> standard_errors_at(const ResidualFunction& residuals, const std::vector<double>& p, double chi2, int n_points,
                                       const std::vector<Bounds>& bounds);

}  // namespace manikind::analysis::reconcile
