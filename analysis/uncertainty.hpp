#pragma once
// GUM building blocks (JCGM 100:2008) for the paper's Eq. S7: U = k u_C = k sqrt(u_A² + u_B²).
#include <cstddef>
#include <limits>
#include <vector>

namespace manikind::analysis {

inline constexpr double kInfiniteDof = std::numeric_limits<double>::infinity();

// How the coverage factor k of U = k u_C (Eq. S7) is chosen.
enum class Coverage {
    welch_satterthwaite,  // GUM G.4: k = t_{(1+p)/2, nu_eff}, nu_eff from Welch-Satterthwaite (default)
    replicates_t,         // Text S3: k = t_{(1+p)/2, n-1} from the replicates alone (4.303 for n = 3)
};
const char* to_string(Coverage c);

struct Estimate {
    double value = 0.0;    // the replicate mean (W/m² for fluxes)
    // Type A: standard deviation of the mean of the replicates (GUM 4.2.3). NaN when it is
    // not estimable (fewer than two replicates), never 0; see type_a_estimable.
    double u_a = 0.0;
    bool type_a_estimable = true;
    double u_b = 0.0;      // Type B: from instrument specifications (GUM 4.3)
    double nu_b = kInfiniteDof;    // Type B degrees of freedom (GUM G.4.2)
    double u_c = 0.0;      // combined standard uncertainty, sqrt(u_A² + u_B²) (Type B only without u_A)
    double nu_eff = kInfiniteDof;  // Welch-Satterthwaite effective degrees of freedom (GUM G.4.1)
    double k_dof = kInfiniteDof;   // the dof k was taken at: nu_eff (GUM) or n - 1 (Text S3)
    double k = 0.0;        // coverage factor t_{(1+p)/2, k_dof}
    double U = 0.0;        // expanded uncertainty k u_C (Eq. S7)
    int n = 0;             // replicates
};

// Arithmetic mean; NaN for an empty list.
double mean(const std::vector<double>& values);
// Sample standard deviation (n - 1 in the denominator); 0 for fewer than two values.
double sample_sd(const std::vector<double>& values);
// Type A of a mean of n replicates: s / sqrt(n) (GUM 4.2.3). NaN for fewer than two values:
// one replicate says nothing about the scatter, and 0 would claim a perfect repeatability.
double type_a_of_mean(const std::vector<double>& values);

// Welch-Satterthwaite (GUM G.2b): nu_eff = u_C⁴ / sum(u_i⁴ / nu_i). Components with infinite
// dof (Type B here) drop out of the sum; infinite when nothing has finite dof or u_i = 0.
struct Component {
    double u = 0.0;
    double dof = kInfiniteDof;
};
double welch_satterthwaite(const std::vector<Component>& components);

// Degrees of freedom of a Type B standard uncertainty whose own relative uncertainty is
// Δu/u (GUM G.4.2, Eq. G.3): nu = 0.5 (Δu/u)^-2, e.g. 0.25 -> 8. Infinite for Δu/u = 0
// (the limits are taken as exactly known, GUM G.4.3).
double type_b_dof(double relative_uncertainty_of_u);

// Two-sided coverage factor from Student's t: k = t_{(1+p)/2, nu}. For nu = 2, p = 0.95,
// k = 4.303 (Text S3, Eq. S7); for infinite nu the normal quantile (1.960).
double coverage_factor(double nu_eff, double confidence = 0.95);

struct CoverageOptions {
    Coverage coverage = Coverage::welch_satterthwaite;
    double type_b_dof = kInfiniteDof;  // GUM G.4.2; infinite = limits exactly known
    double confidence = 0.95;          // the paper's 95 % (Eq. S7)
};

// Combines a Type A (n replicates, dof n - 1) and a Type B standard uncertainty into the
// full Eq. S7 estimate. With n < 2 (or a NaN u_a) Type A is not estimable: u_a = NaN,
// type_a_estimable = false, u_C = u_B and k from Type B alone (either coverage mode: the
// paper's t_{n-1} does not exist for n = 1).
Estimate combine(double value, double u_a, int n_replicates, double u_b, const CoverageOptions& options);
// GUM default: Welch-Satterthwaite with an infinite-dof Type B.
Estimate combine(double value, double u_a, int n_replicates, double u_b, double confidence = 0.95);

}  // namespace manikind::analysis
