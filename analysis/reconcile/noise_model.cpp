#include "analysis/reconcile/noise_model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include <Eigen/Dense>

namespace manikind::analysis::reconcile {
namespace {

struct ZoneData {
    std::vector<double> ss;        // within-case sum of squares
    std::vector<double> dof;       // n_c - 1
    std::vector<double> abs_flux;  // |q| of the case
};

// -2 log-likelihood of one zone (up to a constant): sum_c dof ln v + ss / v.
double neg2_loglik(const ZoneData& d, double sigma0_sq, double kappa) {
    double out = 0.0;
    for (std::size_t c = 0; c < d.ss.size(); ++c) {
        const double v = std::max(sigma0_sq + kappa * kappa * d.abs_flux[c] * d.abs_flux[c], 1e-12);
        out += d.dof[c] * std::log(v) + d.ss[c] / v;
    }
    return out;
}

// A zone's sigma0² is shrunk toward the mean over zones by a scaled inverse-chi² prior of
// `prior_dof` degrees of freedom: with 30 dof per zone a free maximum likelihood can collapse a
// zone's variance to ~0 (all of it put on kappa), which would make that zone look infinitely
// precise. At least kMinPriorDof; more where the zones' own estimates scatter no more than
// their sampling allows (empirical Bayes, best_prior_dof below).
constexpr double kMinPriorDof = 10.0;
// The prior's degrees of freedom tried by best_prior_dof: steps of sqrt(2) from the floor.
constexpr double kPriorDofs[] = {10.0, 14.0, 20.0, 28.0, 40.0, 56.0, 80.0, 113.0, 160.0, 226.0, 320.0};

double objective(const ZoneData& d, double sigma0_sq, double kappa, double prior_sq, double prior_dof) {
    return neg2_loglik(d, sigma0_sq, kappa) + prior_dof * (std::log(std::max(sigma0_sq, 1e-300)) + prior_sq / std::max(sigma0_sq, 1e-300));
}

// How strongly the zones' sigma0² pool: the prior's degrees of freedom that make the zones'
// data most probable, each zone's sigma0² integrated out (the marginal likelihood of a
// scaled inverse-chi²(nu, P) prior, by quadrature on ln sigma0²). Smyth (2004) estimates the
// same hyperparameter for gene-wise variances, by moments. Where every zone scatters alike,
// as on the generator's manikin, a zone's own 30 dof pin its sigma0 to about +-13 % and the
// pooled mean to about +-2 %: a region's term (the head's wet fraction) was planned from its
// zones' own estimate (0.92-1.14 of the head's true noise across 15 campaigns; pooled, 0.97-1.03)
// and named in 45-81 % of the planner's draws at one value across six planning campaigns. A zone
// that really scatters more makes the marginal likelihood fall steeply with nu, so it keeps its
// own variance.
double best_prior_dof(const std::vector<ZoneData>& zones, double kappa, double prior_sq) {
    if (zones.size() < 3 || !(prior_sq > 0.0)) return kMinPriorDof;
    constexpr int kNodes = 97;
    constexpr double kHalfWidth = 4.0;  // ln sigma0² within +-4 of ln P: the likelihoods' mass (30 dof: sd 0.26)
    const double centre = std::log(prior_sq), step = 2.0 * kHalfWidth / (kNodes - 1);
    // Neither a zone's log-likelihood on the nodes nor the prior's shape there depends on nu:
    // ln of the prior's density in t = ln s is norm(nu) - nu/2 (t + P e^-t), with
    // norm(nu) = nu/2 ln(nu P / 2) - ln Gamma(nu/2). Then a log-sum-exp per zone and nu.
    std::vector<std::vector<double>> loglik(zones.size(), std::vector<double>(kNodes));
    std::vector<double> shape(kNodes);
    for (int i = 0; i < kNodes; ++i) {
        const double t = centre - kHalfWidth + step * i;
        shape[static_cast<std::size_t>(i)] = t + prior_sq * std::exp(-t);
        for (std::size_t z = 0; z < zones.size(); ++z) loglik[z][static_cast<std::size_t>(i)] = -0.5 * neg2_loglik(zones[z], std::exp(t), kappa);
    }
    double best = kMinPriorDof, best_value = -std::numeric_limits<double>::infinity();
    for (const double nu : kPriorDofs) {
        const double norm = 0.5 * nu * std::log(0.5 * nu * prior_sq) - std::lgamma(0.5 * nu);
        double total = 0.0;
        for (const auto& ll : loglik) {
            double peak = -std::numeric_limits<double>::infinity();
            for (std::size_t i = 0; i < shape.size(); ++i) peak = std::max(peak, ll[i] - 0.5 * nu * shape[i]);
            double sum = 0.0;
            for (std::size_t i = 0; i < shape.size(); ++i) sum += std::exp(ll[i] - 0.5 * nu * shape[i] - peak);
            total += norm + peak + std::log(sum * step);
        }
        if (total > best_value) best_value = total, best = nu;
    }
    return best;
}

// The zone's sigma0² that minimises the objective for a given kappa. On t = ln(sigma0²) the
// objective is unimodal here; its minimum is where g'(t) = s f'(s) = 0, with (v_c = s + kappa² q_c²)
//   f'(s)  = sum_c dof_c / v_c - ss_c / v_c² + K (1/s - P/s²)
//   f''(s) = sum_c -dof_c / v_c² + 2 ss_c / v_c³ + K (-1/s² + 2 P/s³),  g''(t) = s f'(s) + s² f''(s).
// Newton's method from the kappa = 0 answer (closed form), kept inside a bracket that every
// step narrows by the sign of g' (a step that would leave it bisects): about 6 steps and no
// logarithm, where a golden section over the same bracket took 38 evaluations of 15 logarithms
// each (reconcile estimates the noise model again in every simulated campaign of its null).
// Given start_sq (the zone's answer at the previous kappa or prior, > 0), Newton starts there:
// the estimate calls this some 20 times per zone and step, each a small move from the last
// (this function was a fifth of a null proof's CPU).
double best_sigma0_sq(const ZoneData& d, double kappa, double scale, double prior_sq, double prior_dof,
                      double start_sq = 0.0) {
    const double edge_lo = std::log(1e-8 * scale + 1e-12), edge_hi = std::log(100.0 * scale + 1e-6);
    double lo = edge_lo, hi = edge_hi;
    const double k2 = kappa * kappa;
    auto slope = [&](double t, double* curvature) {
        const double s = std::exp(t);
        double f1 = prior_dof * (1.0 / s - prior_sq / (s * s));
        double f2 = prior_dof * (-1.0 / (s * s) + 2.0 * prior_sq / (s * s * s));
        for (std::size_t c = 0; c < d.ss.size(); ++c) {
            const double v = std::max(s + k2 * d.abs_flux[c] * d.abs_flux[c], 1e-12);
            const double inv = 1.0 / v;
            f1 += d.dof[c] * inv - d.ss[c] * inv * inv;
            f2 += -d.dof[c] * inv * inv + 2.0 * d.ss[c] * inv * inv * inv;
        }
        if (curvature) *curvature = s * f1 + s * s * f2;
        return s * f1;
    };
    // The minimum may be at the bracket's edge (a zone with next to no data): an edge is checked
    // once, when a step would leave the bracket there (a narrowed side is known to hold no minimum).
    bool lo_checked = false, hi_checked = false;
    double ss_sum = prior_dof * prior_sq, dof_sum = prior_dof;
    for (std::size_t c = 0; c < d.ss.size(); ++c) ss_sum += d.ss[c], dof_sum += d.dof[c];
    double t = std::clamp(std::log(std::max(start_sq > 0.0 ? start_sq : ss_sum / dof_sum, 1e-300)), lo, hi);
    for (int i = 0; i < 100 && hi - lo > 1e-12; ++i) {
        double g2 = 0.0;
        const double g1 = slope(t, &g2);
        if (g1 == 0.0) break;
        (g1 > 0.0 ? hi : lo) = t;
        double next = g2 > 0.0 ? t - g1 / g2 : 0.5 * (lo + hi);
        if (!(next > lo && next < hi)) {
            if (next <= lo && lo == edge_lo && !lo_checked) {
                if (slope(lo, nullptr) >= 0.0) return std::exp(lo);
                lo_checked = true;
            } else if (next >= hi && hi == edge_hi && !hi_checked) {
                if (slope(hi, nullptr) <= 0.0) return std::exp(hi);
                hi_checked = true;
            }
            next = 0.5 * (lo + hi);
        }
        if (std::abs(next - t) < 1e-13) {
            t = next;
            break;
        }
        t = next;
    }
    return std::exp(t);
}

// The shared factors' variances T = diag(t) given the zones' variances D. Per case, with
// A = D^-1/2 J, M = A'A, b = A' D^-1/2 h per contrast h, S = sum_h b b' and n contrasts, the part
// of -2 ln L that depends on T is (Woodbury, the determinant lemma)
//   f(T) = sum_c n_c ln det(I + T^1/2 M_c T^1/2) - tr(W_c S_c),   W_c = (T^-1 + M_c)^-1,
// written with T^1/2 so that a variance of exactly zero is an ordinary point. Its derivatives,
// with G_c = (M_c^-1 + T)^-1 = M_c - M_c W_c M_c (Sigma^-1 seen through J: J' Sigma^-1 J):
//   df/dt_k = sum_c n_c G_kk - [(I - G T) S (I - G T)']_kk,   E[d²f/dt_k dt_l] = sum_c n_c G_kl²
// (the expected information of a variance component, Searle, Casella & McCulloch 6.3).
struct FactorStats {
    Eigen::MatrixXd m, s;
    double n = 0.0;
};

struct FactorTerms {
    double value = 0.0;
    Eigen::VectorXd grad;
    Eigen::MatrixXd fisher;
};

// W = (T^-1 + M)^-1 = T^1/2 (I + T^1/2 M T^1/2)^-1 T^1/2 (eta's posterior covariance given one
// contrast), in the form that holds at a variance of zero, and ln det(I + T^1/2 M T^1/2).
struct Posterior {
    Eigen::MatrixXd w;
    double logdet = 0.0;
};

Posterior posterior(const Eigen::MatrixXd& m, const Eigen::VectorXd& t) {
    const Eigen::VectorXd root = t.cwiseMax(0.0).cwiseSqrt();
    Eigen::MatrixXd b = root.asDiagonal() * m * root.asDiagonal();
    b.diagonal().array() += 1.0;
    const Eigen::LLT<Eigen::MatrixXd> llt(b);
    Posterior out;
    for (Eigen::Index i = 0; i < t.size(); ++i) out.logdet += 2.0 * std::log(llt.matrixL()(i, i));
    out.w = root.asDiagonal() * llt.solve(Eigen::MatrixXd(root.asDiagonal()));
    return out;
}

FactorTerms factor_terms(const std::vector<FactorStats>& cases, const Eigen::VectorXd& t, bool derivatives) {
    const Eigen::Index k = t.size();
    FactorTerms out;
    out.grad = Eigen::VectorXd::Zero(k);
    out.fisher = Eigen::MatrixXd::Zero(k, k);
    const Eigen::MatrixXd identity = Eigen::MatrixXd::Identity(k, k);
    for (const auto& c : cases) {
        const auto [w, logdet] = posterior(c.m, t);
        out.value += c.n * logdet - w.cwiseProduct(c.s).sum();
        if (!derivatives) continue;
        const Eigen::MatrixXd g = c.m - c.m * w * c.m;
        const Eigen::MatrixXd u = identity - g * t.asDiagonal();
        out.grad += c.n * g.diagonal() - (u * c.s * u.transpose()).diagonal();
        out.fisher += c.n * g.cwiseAbs2();
    }
    return out;
}

// Minimises f over t >= 0 by Fisher scoring projected on the bound (Bertsekas' projected Newton:
// a variance at zero whose gradient pushes outward stays there, the others take the Newton step,
// halved until f decreases). Where the likelihood's maximum is at zero this reaches it exactly;
// EM only creeps toward it (docs/notes/reconcile-history.md, "Noise model").
void maximise_factors(const std::vector<FactorStats>& cases, Eigen::VectorXd& t) {
    const Eigen::Index k = t.size();
    if (k == 0 || cases.empty()) return;
    FactorTerms cur = factor_terms(cases, t, true);
    for (int step = 0; step < 100; ++step) {
        std::vector<Eigen::Index> free;
        for (Eigen::Index i = 0; i < k; ++i)
            if (cur.fisher(i, i) > 0.0 && (t(i) > 0.0 || cur.grad(i) < 0.0)) free.push_back(i);
        if (free.empty()) return;
        const auto nf = static_cast<Eigen::Index>(free.size());
        Eigen::MatrixXd h(nf, nf);
        Eigen::VectorXd g(nf);
        for (Eigen::Index a = 0; a < nf; ++a) {
            g(a) = cur.grad(free[static_cast<std::size_t>(a)]);
            for (Eigen::Index b = 0; b < nf; ++b) h(a, b) = cur.fisher(free[static_cast<std::size_t>(a)], free[static_cast<std::size_t>(b)]);
        }
        // A ridge of 1e-10 of the largest curvature keeps a near-singular direction (two collinear
        // factors) from a step to infinity; the line search does the rest.
        h.diagonal().array() += 1e-10 * h.diagonal().maxCoeff();
        Eigen::VectorXd d = -h.ldlt().solve(g);
        if (!d.allFinite()) d = -g.cwiseQuotient(h.diagonal());
        bool moved = false;
        for (int half = 0; half < 40 && !moved; ++half) {
            const double alpha = std::ldexp(1.0, -half);
            Eigen::VectorXd trial = t;
            for (Eigen::Index a = 0; a < nf; ++a) {
                const Eigen::Index i = free[static_cast<std::size_t>(a)];
                trial(i) = std::max(0.0, t(i) + alpha * d(a));
            }
            const double value = factor_terms(cases, trial, false).value;
            if (value < cur.value) {
                const double gain = cur.value - value;
                t = trial;
                cur = factor_terms(cases, t, true);
                moved = true;
                if (gain <= 1e-12 * (1.0 + std::abs(value))) return;
            }
        }
        if (!moved) return;  // no decrease along the step: stationary to rounding
    }
}

}  // namespace

Eigen::MatrixXd ScatterModel::trial_covariance(const std::vector<double>& abs_flux, const Eigen::MatrixXd& j) const {
    const auto z_count = static_cast<Eigen::Index>(zone_sd_w_m2.size());
    Eigen::MatrixXd v = Eigen::MatrixXd::Zero(z_count, z_count);
    for (Eigen::Index z = 0; z < z_count; ++z) v(z, z) = variance(static_cast<std::size_t>(z), abs_flux[static_cast<std::size_t>(z)]);
    if (j.cols() > 0 && j.rows() == z_count) {
        Eigen::VectorXd t(j.cols());
        for (Eigen::Index k = 0; k < j.cols(); ++k) t(k) = factor_sd[static_cast<std::size_t>(k)] * factor_sd[static_cast<std::size_t>(k)];
        v += j * t.asDiagonal() * j.transpose();
    }
    return v;
}

ScatterModel estimate_scatter(const ReplicateResiduals& data, int max_iterations) {
    ScatterModel out;
    const std::size_t n_cases = data.residual_w_m2.size();
    if (data.abs_flux_w_m2.size() != n_cases || data.loadings.size() != n_cases)
        throw std::invalid_argument("estimate_scatter: cases disagree");
    const auto k_count = static_cast<Eigen::Index>(data.factor_start_sd.size());
    std::size_t n_zones = 0;
    for (const auto& c : data.residual_w_m2)
        if (!c.empty()) n_zones = std::max(n_zones, c.front().size());
    const auto z_count = static_cast<Eigen::Index>(n_zones);
    out.zone_sd_w_m2.assign(n_zones, 0.0);
    out.factor_sd = data.factor_start_sd;

    // Helmert contrasts of each case's trials: n - 1 independent vectors with the trial covariance.
    std::vector<std::vector<Eigen::VectorXd>> contrasts(n_cases);
    double pooled_ss = 0.0, pooled_dof = 0.0;
    for (std::size_t c = 0; c < n_cases; ++c) {
        std::vector<Eigen::VectorXd> trials;
        for (const auto& t : data.residual_w_m2[c]) {
            if (t.size() != n_zones) continue;
            Eigen::VectorXd v(z_count);
            bool finite = true;
            for (Eigen::Index z = 0; z < z_count; ++z) {
                v(z) = t[static_cast<std::size_t>(z)];
                finite = finite && std::isfinite(v(z));
            }
            if (finite) trials.push_back(std::move(v));
        }
        if (trials.size() < 2) continue;
        if (data.loadings[c].rows() != z_count || data.loadings[c].cols() != k_count)
            throw std::invalid_argument("estimate_scatter: loadings do not match the zones and factors");
        Eigen::VectorXd sum = trials[0];
        for (std::size_t k = 1; k < trials.size(); ++k) {
            const double kk = static_cast<double>(k);
            contrasts[c].push_back((sum - kk * trials[k]) / std::sqrt(kk * (kk + 1.0)));
            sum += trials[k];
            pooled_ss += contrasts[c].back().squaredNorm();
            pooled_dof += static_cast<double>(z_count);
        }
        out.dof += static_cast<int>(trials.size()) - 1;
    }
    if (out.dof == 0 || pooled_dof <= 0.0) return out;
    out.estimable = true;
    const double scale = std::max(pooled_ss / pooled_dof, 1e-12);
    std::vector<double> sigma_sq(n_zones, 0.5 * scale);
    double kappa = 0.0;
    Eigen::VectorXd tau_sq(k_count);
    for (Eigen::Index k = 0; k < k_count; ++k) tau_sq(k) = out.factor_sd[static_cast<std::size_t>(k)] * out.factor_sd[static_cast<std::size_t>(k)];

    // The zones' variances v_cz = sigma0_z² + (kappa q_cz)² of each case, floored.
    auto zone_inverse = [&](std::size_t c) {
        Eigen::VectorXd d_inv(z_count);
        for (Eigen::Index z = 0; z < z_count; ++z) {
            const double q = data.abs_flux_w_m2[c][static_cast<std::size_t>(z)];
            d_inv(z) = 1.0 / std::max(sigma_sq[static_cast<std::size_t>(z)] + kappa * kappa * q * q, 1e-9 * scale);
        }
        return d_inv;
    };
    // -2 ln L of the contrasts (plus the zones' prior), the quantity every step lowers; and the
    // shared factors' statistics under the current zone variances.
    std::vector<FactorStats> factor_cases;
    auto refresh_factor_stats = [&]() {
        factor_cases.clear();
        double zone_part = 0.0;
        for (std::size_t c = 0; c < n_cases; ++c) {
            if (contrasts[c].empty()) continue;
            const Eigen::VectorXd d_inv = zone_inverse(c);
            const Eigen::MatrixXd& j = data.loadings[c];
            FactorStats f;
            f.n = static_cast<double>(contrasts[c].size());
            f.m = j.transpose() * d_inv.asDiagonal() * j;
            f.s = Eigen::MatrixXd::Zero(k_count, k_count);
            zone_part -= f.n * d_inv.array().log().sum();
            for (const auto& h : contrasts[c]) {
                const Eigen::VectorXd bv = j.transpose() * d_inv.cwiseProduct(h);
                f.s += bv * bv.transpose();
                zone_part += h.cwiseAbs2().dot(d_inv);
            }
            factor_cases.push_back(std::move(f));
        }
        return zone_part;
    };

    // Expectation-conditional maximisation (ECME, Liu & Rubin 1994): an EM step for the zones'
    // sigma0 and kappa with the factors latent, then the factors' variances maximised on the
    // likelihood itself given those, until nothing moves. Every step lowers -2 ln L.
    // The zones' prior starts at its floor; once the likelihood settles, its degrees of freedom
    // are chosen from the zones' data (best_prior_dof) and, where that moved them, the estimate
    // goes on under the new prior (the grid's steps make this end: at most a few rounds).
    double prior_dof = kMinPriorDof;
    int prior_rounds = 0;
    double last_objective = std::numeric_limits<double>::infinity();
    for (int it = 0; it < max_iterations; ++it) {
        // E-step: the shared factors of each contrast given the current variances.
        std::vector<ZoneData> zones(n_zones);
        for (std::size_t c = 0; c < n_cases; ++c) {
            if (contrasts[c].empty()) continue;
            const Eigen::MatrixXd& j = data.loadings[c];
            const Eigen::VectorXd d_inv = zone_inverse(c);
            Eigen::MatrixXd post_cov = Eigen::MatrixXd::Zero(k_count, k_count);
            Eigen::VectorXd explained_var = Eigen::VectorXd::Zero(z_count);
            if (k_count > 0) {
                // Posterior covariance of eta, T - T J'(D + J T J')^-1 J T.
                post_cov = posterior(j.transpose() * d_inv.asDiagonal() * j, tau_sq).w;
                explained_var = (j * post_cov * j.transpose()).diagonal();
            }
            std::vector<double> ss(n_zones, 0.0);
            for (const auto& h : contrasts[c]) {
                Eigen::VectorXd resid = h;
                if (k_count > 0) resid -= j * (post_cov * (j.transpose() * d_inv.cwiseProduct(h)));
                for (Eigen::Index z = 0; z < z_count; ++z)
                    ss[static_cast<std::size_t>(z)] += resid(z) * resid(z) + explained_var(z);
            }
            for (std::size_t z = 0; z < n_zones; ++z) {
                zones[z].ss.push_back(ss[z]);
                zones[z].dof.push_back(static_cast<double>(contrasts[c].size()));
                zones[z].abs_flux.push_back(data.abs_flux_w_m2[c][z]);
            }
        }
        // M-step for the zones: sigma0 per zone and the shared kappa.
        double prior_sq = 0.0;
        for (double v : sigma_sq) prior_sq += v / static_cast<double>(n_zones);
        auto total = [&](double kap, std::vector<double>* s2) {
            double sum = 0.0;
            for (std::size_t z = 0; z < n_zones; ++z) {
                const double v = best_sigma0_sq(zones[z], kap, scale, prior_sq, prior_dof, sigma_sq[z]);
                if (s2) (*s2)[z] = v;
                sum += objective(zones[z], v, kap, prior_sq, prior_dof);
            }
            return sum;
        };
        double best_value = total(kappa, nullptr);
        for (double step : {0.004, 0.001, 0.0003})
            for (double kap : {kappa - step, kappa + step})
                if (kap >= 0.0 && kap <= 0.2) {
                    const double v = total(kap, nullptr);
                    if (v < best_value) {
                        best_value = v;
                        kappa = kap;
                    }
                }
        // The prior's scale is the zones' mean sigma0², and each sigma0² leans on it: solved
        // together (a secant on P - mean_z sigma0_z²(P)) rather than one lag per step, which under a
        // strong prior (80-320 dof against a zone's 30) crept for hundreds of steps.
        auto mean_given = [&](double p) {
            prior_sq = p;
            total(kappa, &sigma_sq);
            double m = 0.0;
            for (double v : sigma_sq) m += v / static_cast<double>(n_zones);
            return m - p;
        };
        double p0 = prior_sq, g0 = mean_given(p0);
        if (prior_dof > kMinPriorDof && std::abs(g0) > 1e-9 * p0) {
            double p1 = p0 + g0, g1 = mean_given(p1);
            for (int i = 0; i < 10 && std::abs(g1) > 1e-9 * p1 && g1 != g0; ++i) {
                double p2 = p1 - g1 * (p1 - p0) / (g1 - g0);
                if (!(p2 > 0.0)) p2 = 0.5 * p1;
                p0 = p1, g0 = g1, p1 = p2;
                g1 = mean_given(p1);
            }
        }
        // The factors' variances, maximised given the zones (not an EM step: see maximise_factors).
        const double zone_part = refresh_factor_stats();
        maximise_factors(factor_cases, tau_sq);
        double objective_now = zone_part + factor_terms(factor_cases, tau_sq, false).value;
        for (double v : sigma_sq) objective_now += prior_dof * (std::log(v) + prior_sq / v);
        out.iterations = it + 1;
        // Converged when a step changes -2 ln L by less than 1e-7 (a likelihood ratio of 1 to
        // 1e-7: no estimate downstream can tell the difference) under a prior that the zones'
        // data no longer move.
        // The prior is first chosen once the likelihood has nearly settled (a change below 0.01):
        // from there its choice no longer moves, and the estimate settles once, not twice.
        const double change = std::abs(last_objective - objective_now);
        if (change < 1e-7 || (prior_rounds == 0 && change < 1e-2)) {
            const double nu = best_prior_dof(zones, kappa, prior_sq);
            const bool settled = change < 1e-7;
            if (prior_rounds++ > 4 || (nu == prior_dof && settled)) {
                out.converged = settled;
                break;
            }
            if (nu != prior_dof) {
                prior_dof = nu;
                last_objective = std::numeric_limits<double>::infinity();
                continue;
            }
        }
        last_objective = objective_now;
    }
    out.zone_prior_dof = prior_dof;
    out.relative_sd = kappa;
    for (std::size_t z = 0; z < n_zones; ++z) out.zone_sd_w_m2[z] = std::sqrt(sigma_sq[z]);
    for (Eigen::Index k = 0; k < k_count; ++k) out.factor_sd[static_cast<std::size_t>(k)] = std::sqrt(std::max(tau_sq(k), 0.0));
    return out;
}

ReplicateResiduals simulate_residuals(const ReplicateResiduals& shape, const ScatterModel& truth, std::uint64_t seed) {
    ReplicateResiduals out = shape;
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> gauss(0.0, 1.0);
    for (std::size_t c = 0; c < out.residual_w_m2.size(); ++c) {
        const Eigen::MatrixXd& j = out.loadings.at(c);
        for (auto& trial : out.residual_w_m2[c]) {
            Eigen::VectorXd eta(j.cols());
            for (Eigen::Index k = 0; k < j.cols(); ++k)
                eta(k) = gauss(rng) * (static_cast<std::size_t>(k) < truth.factor_sd.size() ? truth.factor_sd[static_cast<std::size_t>(k)] : 0.0);
            const Eigen::VectorXd shared = j * eta;
            for (std::size_t z = 0; z < trial.size(); ++z) {
                const double v = z < truth.zone_sd_w_m2.size() ? truth.variance(z, out.abs_flux_w_m2[c].at(z)) : 0.0;
                trial[z] = gauss(rng) * std::sqrt(v) + (static_cast<Eigen::Index>(z) < shared.size() ? shared(static_cast<Eigen::Index>(z)) : 0.0);
            }
        }
    }
    return out;
}

}  // namespace manikind::analysis::reconcile
