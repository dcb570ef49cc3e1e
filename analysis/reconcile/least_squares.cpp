#include "analysis/reconcile/least_squares.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>

namespace manikind::analysis::reconcile {
namespace {

constexpr double kSettledChi2 = 1e-8;  // relative to 1 + chi2

double sum_squares(const std::vector<double>& r) {
    double s = 0.0;
    for (double x : r) s += x * x;
    return s;
}

void clamp_to(std::vector<double>& p, const std::vector<Bounds>& b) {
    for (std::size_t i = 0; i < p.size(); ++i) p[i] = std::clamp(p[i], b[i].lo, b[i].hi);
}

Eigen::MatrixXd jacobian(const ResidualFunction& f, const std::vector<double>& p, const std::vector<double>& r0,
                         const std::vector<Bounds>& b) {
    Eigen::MatrixXd j(r0.size(), p.size());
    for (std::size_t k = 0; k < p.size(); ++k) {
        const double span = b[k].hi - b[k].lo;
        double step = 1e-6 * std::max(span, 1e-9) + 1e-7 * std::abs(p[k]);
        std::vector<double> q = p;
        // Step inward at an upper bound so the derivative stays inside the allowed range.
        if (q[k] + step > b[k].hi) step = -step;
        q[k] += step;
        const std::vector<double> r1 = f(q);
        for (std::size_t i = 0; i < r0.size(); ++i) j(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = (r1[i] - r0[i]) / step;
    }
    return j;
}

}  // namespace

FitResult fit_weighted_least_squares(const ResidualFunction& f, std::vector<double> p, const std::vector<Bounds>& b,
                                     int max_iterations, bool with_errors) {
    clamp_to(p, b);
    std::vector<double> r = f(p);
    double chi2 = sum_squares(r);
    double lambda = 1e-3;
    FitResult out;
    const auto n_params = static_cast<Eigen::Index>(p.size());
    for (int it = 0; it < max_iterations; ++it) {
        out.iterations = it + 1;
        const Eigen::MatrixXd j = jacobian(f, p, r, b);
        const Eigen::Map<const Eigen::VectorXd> rv(r.data(), static_cast<Eigen::Index>(r.size()));
        const Eigen::MatrixXd jtj = j.transpose() * j;
        const Eigen::VectorXd jtr = j.transpose() * rv;
        bool improved = false;
        // Converged when a step gains, or the linear model promises, less than 1e-8 (1 + chi2):
        // a chi2 of 500 settled to 5e-6, a parameter within about 0.3 % of its standard error
        // (issue 62: 1e-9 and a cascade of 12 refused steps at the end cost a fifth of the fits'
        // predictions and moved no answer).
        const double settled = kSettledChi2 * (1.0 + chi2);
        for (int tries = 0; tries < 12 && !improved; ++tries) {
            Eigen::MatrixXd a = jtj;
            for (Eigen::Index i = 0; i < n_params; ++i) a(i, i) += lambda * std::max(jtj(i, i), 1e-12);
            const Eigen::VectorXd step = a.ldlt().solve(-jtr);
            std::vector<double> q = p;
            for (Eigen::Index i = 0; i < n_params; ++i) q[static_cast<std::size_t>(i)] += step(i);
            clamp_to(q, b);
            // |r + J s|² = chi2 + 2 s'J'r + s'J'J s for the step s taken (after the bounds).
            Eigen::VectorXd taken(n_params);
            for (Eigen::Index i = 0; i < n_params; ++i) taken(i) = q[static_cast<std::size_t>(i)] - p[static_cast<std::size_t>(i)];
            if (-(2.0 * taken.dot(jtr) + taken.dot(jtj * taken)) < settled) {
                out.converged = true;
                break;
            }
            const std::vector<double> rq = f(q);
            const double chi2_q = sum_squares(rq);
            if (std::isfinite(chi2_q) && chi2_q < chi2) {
                const double gain = chi2 - chi2_q;
                p = q;
                r = rq;
                chi2 = chi2_q;
                lambda = std::max(lambda / 10.0, 1e-9);
                improved = true;
                if (gain < settled) out.converged = true;
            } else {
                lambda *= 10.0;
            }
        }
        if (!improved || out.converged) {
            out.converged = true;
            break;
        }
    }
    out.parameters = p;
    out.chi2 = chi2;
    out.n_points = static_cast<int>(r.size());
    if (with_errors) out.standard_errors = standard_errors_at(f, p, chi2, out.n_points, b);
    return out;
}

std::vector<double> standard_errors_at(const ResidualFunction& f, const std::vector<double>& p, double chi2, int n_points,
                                       const std::vector<Bounds>& b) {
    const auto n_params = static_cast<Eigen::Index>(p.size());
    const auto rows = static_cast<Eigen::Index>(std::max(0, n_points));
    // Covariance from the curvature over a finite step (1/120 of each parameter's range, central):
    // a derivative at a point overstates the information where the physics has a kink
    // (|dT|^(1/4) at dT = 0). Inflated by the Birge ratio when the fit is worse than its noise.
    Eigen::MatrixXd j(rows, n_params);
    for (Eigen::Index k = 0; k < n_params; ++k) {
        const auto kk = static_cast<std::size_t>(k);
        const double h = (b[kk].hi - b[kk].lo) / 120.0;
        std::vector<double> up = p, down = p;
        up[kk] = std::min(p[kk] + h, b[kk].hi);
        down[kk] = std::max(p[kk] - h, b[kk].lo);
        const std::vector<double> ru = f(up), rd = f(down);
        for (Eigen::Index i = 0; i < rows; ++i)
            j(i, k) = (ru[static_cast<std::size_t>(i)] - rd[static_cast<std::size_t>(i)]) / std::max(up[kk] - down[kk], 1e-300);
    }
    const Eigen::MatrixXd jtj = j.transpose() * j;
    const int dof = std::max(1, n_points - static_cast<int>(p.size()));
    const double birge = std::max(1.0, chi2 / dof);
    std::vector<double> se(p.size(), std::numeric_limits<double>::infinity());
    Eigen::FullPivLU<Eigen::MatrixXd> lu(jtj);
    if (lu.isInvertible()) {
        const Eigen::MatrixXd cov = lu.inverse() * birge;
        for (Eigen::Index i = 0; i < n_params; ++i) se[static_cast<std::size_t>(i)] = std::sqrt(std::max(0.0, cov(i, i)));
    }
    return se;
}

}  // namespace manikind::analysis::reconcile
