#include "analysis/interlab.hpp"
#include "analysis/recording.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

#include <boost/math/distributions/fisher_f.hpp>

namespace manikind::analysis {

namespace {

void validate(const std::vector<LabCell>& cells) {
    if (cells.size() < 2)
        throw std::invalid_argument("estimate_precision: at least 2 laboratories are needed, got " +
                                    std::to_string(cells.size()));
    for (const auto& c : cells) {
        if (c.results.size() < 2)
            throw std::invalid_argument("estimate_precision: laboratory '" + c.lab_id + "' has " +
                                        std::to_string(c.results.size()) +
                                        " result(s); at least 2 replicates are needed for s_i");
        for (double y : c.results)
            if (!std::isfinite(y))
                throw std::invalid_argument("estimate_precision: laboratory '" + c.lab_id +
                                            "' has a non-finite result");
    }
}

// Cochran's test assumes equal n; 7.3.3.1 applies it with the n of the majority of cells. On a
// tie the smaller n is taken: its critical value is higher, so fewer cells are flagged.
int majority_n(const std::vector<LabCellSummary>& cells) {
    std::map<int, int> counts;
    for (const auto& c : cells) ++counts[c.n];
    int best = 0;
    int best_count = 0;
    for (const auto& [n, count] : counts)  // ascending n: '>' keeps the smallest n on a tie
        if (count > best_count) best = n, best_count = count;
    return best;
}

}  // namespace

double cochran_critical(int labs, int replicates, double alpha) {
    // Only the range of ISO 5725-2 Table 4; outside it the outcome is left empty.
    if (labs < 2 || labs > 40 || replicates < 2 || replicates > 6 || !(alpha > 0.0 && alpha < 1.0)) return kNaN;
    // Cochran (1941): with nu = n - 1, C_crit = 1 / (1 + (p - 1) / F), F the upper alpha/p point of
    // F(nu, (p - 1) nu). Exact when C_crit > 1/2 (two cells cannot both exceed half the sum) and a
    // Bonferroni bound otherwise; the published tables (Table 4, Eisenhart et al. 1947) are built
    // this way, and the unit test checks it against printed values.
    const double nu = replicates - 1.0;
    const double p = labs;
    const boost::math::fisher_f_distribution<double> f(nu, (p - 1.0) * nu);
    const double f_crit = boost::math::quantile(boost::math::complement(f, alpha / p));
    return 1.0 / (1.0 + (p - 1.0) / f_crit);
}

PrecisionEstimate estimate_precision(const std::vector<LabCell>& cells) {
    validate(cells);
    PrecisionEstimate e;
    e.labs = static_cast<int>(cells.size());
    const double p = e.labs;

    // Cell averages and standard deviations (7.2); two-pass for accuracy with large offsets.
    // T2 = Σ n_i ȳ_i² is not accumulated: the between-cell term below uses deviations instead.
    double t1 = 0.0, t3 = 0.0, t4 = 0.0, t5 = 0.0;
    e.cells.reserve(cells.size());
    for (const auto& c : cells) {
        LabCellSummary s;
        s.lab_id = c.lab_id;
        s.n = static_cast<int>(c.results.size());
        const double n = s.n;
        double sum = 0.0;
        for (double y : c.results) sum += y;
        s.mean = sum / n;
        double ss = 0.0;
        for (double y : c.results) ss += (y - s.mean) * (y - s.mean);
        s.sd = std::sqrt(ss / (n - 1.0));
        t1 += n * s.mean;                 // T1 = Σ n_i ȳ_i     (7.4.5)
        t3 += n;                          // T3 = Σ n_i
        t4 += n * n;                      // T4 = Σ n_i²
        t5 += (n - 1.0) * s.sd * s.sd;    // T5 = Σ (n_i - 1) s_i²
        e.cells.push_back(std::move(s));
    }

    e.grand_mean = t1 / t3;  // m̂ = T1 / T3 (7.4.5)
    const double s_r2 = t5 / (t3 - p);  // s_r² = T5 / (T3 - p) (7.4.5)
    // s_L² = [(T2 T3 - T1²) / (T3 (p - 1)) - s_r²] · T3 (p - 1) / (T3² - T4) (7.4.5). The first
    // term, the between-cell mean square, is computed from deviations about m̂: algebraically
    // (T2 T3 - T1²) / T3 = Σ n_i (ȳ_i - m̂)², without T2 T3 - T1² cancelling catastrophically
    // when the level is large against the spread of the means.
    double ss_between = 0.0;
    for (const auto& s : e.cells) ss_between += s.n * (s.mean - e.grand_mean) * (s.mean - e.grand_mean);
    const double s_d2 = ss_between / (p - 1.0);
    e.between_lab_variance_raw = (s_d2 - s_r2) * t3 * (p - 1.0) / (t3 * t3 - t4);
    const double s_l2 = std::max(0.0, e.between_lab_variance_raw);  // negative -> 0 (7.4.5)
    e.repeatability_sd = std::sqrt(s_r2);
    e.between_lab_sd = std::sqrt(s_l2);
    e.reproducibility_sd = std::sqrt(s_r2 + s_l2);  // s_R² = s_r² + s_L² (7.4.5)
    e.repeatability_limit = 2.8 * e.repeatability_sd;      // r = 2.8 s_r
    e.reproducibility_limit = 2.8 * e.reproducibility_sd;  // R = 2.8 s_R

    // Mandel's h and k (7.3.1): h_i = (ȳ_i - ȳ) / sqrt(Σ (ȳ_i - ȳ)² / (p - 1)) with ȳ the
    // unweighted average of the cell averages; k_i = s_i sqrt(p) / sqrt(Σ s_i²).
    double mean_of_means = 0.0;
    double sum_s2 = 0.0;
    double max_s2 = 0.0;
    for (const auto& s : e.cells) {
        mean_of_means += s.mean / p;
        sum_s2 += s.sd * s.sd;
        max_s2 = std::max(max_s2, s.sd * s.sd);
    }
    double ss_means = 0.0;
    for (const auto& s : e.cells) ss_means += (s.mean - mean_of_means) * (s.mean - mean_of_means);
    const double sd_means = std::sqrt(ss_means / (p - 1.0));
    const double rms_s = std::sqrt(sum_s2 / p);
    for (auto& s : e.cells) {
        // Undefined (0/0) when the means, or the standard deviations, are all identical.
        s.mandel_h = sd_means > 0.0 ? (s.mean - mean_of_means) / sd_means : kNaN;
        s.mandel_k = rms_s > 0.0 ? s.sd / rms_s : kNaN;
    }

    // Cochran's C = s_max² / Σ s_i² (7.3.3), a one-sided test for the largest cell variance.
    e.cochran_c = sum_s2 > 0.0 ? max_s2 / sum_s2 : kNaN;
    e.cochran_n = majority_n(e.cells);
    e.cochran_critical_5pct = cochran_critical(e.labs, e.cochran_n, 0.05);
    e.cochran_critical_1pct = cochran_critical(e.labs, e.cochran_n, 0.01);
    if (std::isfinite(e.cochran_c) && std::isfinite(e.cochran_critical_5pct) &&
        std::isfinite(e.cochran_critical_1pct)) {
        // 7.3.2.2: <= 5 % critical: accepted; > 5 % and <= 1 %: straggler; > 1 %: outlier.
        if (e.cochran_c > e.cochran_critical_1pct)
            e.cochran_outcome = "outlier";
        else if (e.cochran_c > e.cochran_critical_5pct)
            e.cochran_outcome = "straggler";
    }
    return e;
}

}  // namespace manikind::analysis
