#pragma once
// GUM building blocks (JCGM 100:2008) for the paper's Eq. S7: U = k u_C = k sqrt(u_A² + u_B²).
#include <cstddef>
#include <limits>
#include <vector>

namespace manikind::analysis {

inline constexpr double kInfiniteDof = std::numeric_limits<double>::infinity();

struct Estimate {
    double value = 0.0;    // the replicate mean (W/m² for fluxes)
    double u_a = 0.0;      // Type A: standard deviation of the mean of the replicates (GUM 4.2.3)
    double u_b = 0.0;      // Type B: from instrument specifications (GUM 4.3)
    double u_c = 0.0;      // combined standard uncertainty, sqrt(u_A² + u_B²)
    double nu_eff = kInfiniteDof;  // Welch-Satterthwaite effective degrees of freedom (GUM G.4.1)
    double k = 0.0;        // coverage factor t_{(1+p)/2, nu_eff}
    double U = 0.0;        // expanded uncertainty k u_C (Eq. S7)
    int n = 0;             // replicates
};

// Arithmetic mean; NaN for an empty list.
double mean(const std::vector<double>& values);
// Sample standard deviation (n - 1 in the denominator); 0 for fewer than two values.
double sample_sd(const std::vector<double>& values);
// Type A of a mean of n replicates: s / sqrt(n) (GUM 4.2.3); 0 for fewer than two values.
double type_a_of_mean(const std::vector<double>& values);

// Welch-Satterthwaite (GUM G.2b): nu_eff = u_C⁴ / sum(u_i⁴ / nu_i). Components with infinite
// dof (Type B here) drop out of the sum; infinite when nothing has finite dof or u_i = 0.
struct Component {
    double u = 0.0;
    double dof = kInfiniteDof;
};
double welch_satterthwaite(const std::vector<Component>& components);

// Two-sided coverage factor from Student's t: k = t_{(1+p)/2, nu}. For nu = 2, p = 0.95,
// k = 4.303 (Text S3, Eq. S7); for infinite nu the normal quantile (1.960).
double coverage_factor(double nu_eff, double confidence = 0.95);

// Combines a Type A (n replicates, dof n - 1) and a Type B (infinite dof) standard
// uncertainty into the full Eq. S7 estimate.
Estimate combine(double value, double u_a, int n_replicates, double u_b, double confidence = 0.95);

}  // namespace manikind::analysis
