#include "analysis/uncertainty.hpp"

#include <cmath>
#include <stdexcept>

#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>

namespace manikind::analysis {

double mean(const std::vector<double>& values) {
    if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
    double sum = 0.0;
    for (double v : values) sum += v;
    return sum / static_cast<double>(values.size());
}

double sample_sd(const std::vector<double>& values) {
    if (values.size() < 2) return 0.0;
    const double m = mean(values);
    double ss = 0.0;
    for (double v : values) ss += (v - m) * (v - m);
    return std::sqrt(ss / static_cast<double>(values.size() - 1));
}

const char* to_string(Coverage c) {
    return c == Coverage::replicates_t ? "replicates_t" : "welch_satterthwaite";
}

double type_a_of_mean(const std::vector<double>& values) {
    if (values.size() < 2) return std::numeric_limits<double>::quiet_NaN();  // not estimable
    return sample_sd(values) / std::sqrt(static_cast<double>(values.size()));
}

double welch_satterthwaite(const std::vector<Component>& components) {
    double u_c2 = 0.0;
    double denominator = 0.0;
    for (const auto& c : components) {
        u_c2 += c.u * c.u;
        if (std::isfinite(c.dof) && c.u > 0.0) {
            if (!(c.dof > 0.0)) throw std::invalid_argument("welch_satterthwaite: degrees of freedom must be positive");
            denominator += std::pow(c.u, 4) / c.dof;
        }
    }
    if (denominator <= 0.0) return kInfiniteDof;
    return u_c2 * u_c2 / denominator;
}

double coverage_factor(double nu_eff, double confidence) {
    if (!(confidence > 0.0 && confidence < 1.0)) throw std::invalid_argument("coverage_factor: confidence must be in (0, 1)");
    const double tail = (1.0 - confidence) / 2.0;
    // Beyond ~1e6 dof Student's t equals the normal distribution to many digits.
    if (!std::isfinite(nu_eff) || nu_eff > 1e6) {
        return boost::math::quantile(boost::math::complement(boost::math::normal_distribution<double>(), tail));
    }
    if (!(nu_eff > 0.0)) throw std::invalid_argument("coverage_factor: degrees of freedom must be positive");
    // In double throughout: Boost's default promotes to long double (x87), and these quantiles
    // were the costliest part of summarising a campaign; k needs 4 digits, double gives 15.
    using DoublePolicy = boost::math::policies::policy<boost::math::policies::promote_double<false>>;
    return boost::math::quantile(
        boost::math::complement(boost::math::students_t_distribution<double, DoublePolicy>(nu_eff), tail));
}

double type_b_dof(double relative_uncertainty_of_u) {
    if (!(relative_uncertainty_of_u >= 0.0) || !std::isfinite(relative_uncertainty_of_u))
        throw std::invalid_argument("type_b_dof: the relative uncertainty of u_B must be >= 0");
    if (relative_uncertainty_of_u == 0.0) return kInfiniteDof;
    return 0.5 / (relative_uncertainty_of_u * relative_uncertainty_of_u);  // GUM Eq. G.3
}

Estimate combine(double value, double u_a, int n_replicates, double u_b, const CoverageOptions& o) {
    Estimate e;
    e.value = value;
    e.n = n_replicates;
    e.type_a_estimable = n_replicates >= 2 && std::isfinite(u_a);
    e.u_a = e.type_a_estimable ? u_a : std::numeric_limits<double>::quiet_NaN();
    e.u_b = u_b;
    e.nu_b = o.type_b_dof;
    const double u_a2 = e.type_a_estimable ? u_a * u_a : 0.0;  // absent, not zero: U covers Type B only
    e.u_c = std::sqrt(u_a2 + u_b * u_b);  // Eq. S7
    if (e.type_a_estimable) {
        const double type_a_dof = static_cast<double>(n_replicates - 1);
        e.nu_eff = welch_satterthwaite({{u_a, type_a_dof}, {u_b, o.type_b_dof}});  // GUM G.2b
        e.k_dof = o.coverage == Coverage::replicates_t ? type_a_dof : e.nu_eff;  // Text S3 or GUM G.4
    } else {
        e.nu_eff = welch_satterthwaite({{u_b, o.type_b_dof}});
        e.k_dof = e.nu_eff;
    }
    e.k = coverage_factor(e.k_dof, o.confidence);
    e.U = e.k * e.u_c;  // Eq. S7
    return e;
}

Estimate combine(double value, double u_a, int n_replicates, double u_b, double confidence) {
    CoverageOptions o;
    o.confidence = confidence;
    return combine(value, u_a, n_replicates, u_b, o);
}

}  // namespace manikind::analysis
