#pragma once
// ISO 5725-2:1994 precision statistics for one level (one test case) of an inter-laboratory
// study: repeatability s_r, between-laboratory s_L and reproducibility s_R standard deviations,
// with Mandel's h and k (7.3.1) and Cochran's test (7.3.3) for scrutinising the cells.
// Every standard deviation, mean and limit is in the unit of the results (W/m² for fluxes,
// m²·K/W for insulations, ...); h, k and C are dimensionless.
#include <string>
#include <vector>

namespace manikind::analysis {

// One laboratory's replicate test results at one level (a "cell", ISO 5725-2 7.2).
struct LabCell {
    std::string lab_id;
    std::vector<double> results;  // unit of the results
};

struct LabCellSummary {
    std::string lab_id;
    int n = 0;              // replicates n_i
    double mean = 0.0;      // cell average ȳ_i (7.2), unit of the results
    double sd = 0.0;        // cell standard deviation s_i (7.2, n_i - 1 denominator), unit of the results
    double mandel_h = 0.0;  // between-laboratory consistency (7.3.1); NaN when all cell means are equal
    double mandel_k = 0.0;  // within-laboratory consistency (7.3.1); NaN when every s_i is 0
};

struct PrecisionEstimate {
    int labs = 0;                          // p
    double grand_mean = 0.0;               // m̂ = T1 / T3 (7.4.5, unequal n)
    double repeatability_sd = 0.0;         // s_r = sqrt(T5 / (T3 - p)) (7.4.5)
    // s_L (7.4.5); 0 when the estimate of s_L² is negative, as 7.4.5 prescribes.
    double between_lab_sd = 0.0;
    double between_lab_variance_raw = 0.0; // the s_L² estimate before clamping (may be < 0)
    double reproducibility_sd = 0.0;       // s_R = sqrt(s_r² + s_L²) (7.4.5)
    double repeatability_limit = 0.0;      // r = 2.8 s_r (ISO 5725-6: 2.8 ≈ 1.96·√2, 95 %)
    double reproducibility_limit = 0.0;    // R = 2.8 s_R
    // Cochran's C = s_max² / Σ s_i² (7.3.3); NaN when every s_i is 0.
    double cochran_c = 0.0;
    int cochran_n = 0;                     // n the critical values were taken at (the most frequent n_i, 7.3.3.1)
    double cochran_critical_5pct = 0.0;    // NaN when outside the supported range (see cochran_critical)
    double cochran_critical_1pct = 0.0;
    // "" (accepted or not computable) | "straggler" (C > 5 % critical) | "outlier" (C > 1 % critical), 7.3.2.2.
    std::string cochran_outcome;
    std::vector<LabCellSummary> cells;     // in the order given
};

// Upper critical value of Cochran's C for p laboratories with n replicates each at significance
// alpha (0.05 or 0.01 for ISO 5725-2 Table 4). NaN outside 2 <= p <= 40, 2 <= n <= 6 (the range
// of Table 4) or for alpha outside (0, 1).
double cochran_critical(int labs, int replicates, double alpha);

// Precision of one level. Throws std::invalid_argument for fewer than two laboratories, a
// laboratory with fewer than two results, or a non-finite result. The statistics are computed on
// every cell given: removing stragglers/outliers (7.3.4-7.3.5) is the caller's decision.
PrecisionEstimate estimate_precision(const std::vector<LabCell>& cells);

}  // namespace manikind::analysis
