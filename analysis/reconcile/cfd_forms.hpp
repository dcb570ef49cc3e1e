#pragma once
// How well do the paper's CFD whole-body coefficients (Tables S8-S10) pin down the humidity
// coupling gamma in the buoyancy drive N = dT + gamma dC?  Fits two forms with gamma free:
//   Eq. 7:           h = h0 + B |dT + gamma dC|^(1/4)   (h0, B, gamma free)
//   Eq. S8 shape:    h = a |dT + gamma dC|^0.3          (a, gamma free)
// under three weightings, and combines the gammas into one value whose uncertainty includes the
// spread across forms and weightings. Compared with theory (beta_C alpha/(beta_T D) ~ 146) and
// with Eq. 8 (h0 = 0.3, B = 1.25, gamma = 146). Pure: no I/O.
#include <string>
#include <vector>

namespace manikind::analysis::reconcile {

// One whole-body CFD case: dT = skin - air, dC = C_sat(skin) - C_air (wet skin).
struct CfdHObservation {
    int case_id = 0;
    double air_temp_c = 0.0;
    double air_rh_pct = 0.0;
    double skin_temp_c = 35.0;
    double h_w_m2k = 0.0;
};

enum class CfdForm {
    eq7_quarter,   // Eq. 7: h0 + B |N|^(1/4)
    s8_power_0_3,  // Eq. S8 shape: a |N|^0.3
};

enum class CfdWeighting {
    absolute_5pct,  // residual (h_fit - h)/u, u = 5 % of each case's h (CFD quasi-steady variation)
    equal,          // residual (h_fit - h)/u, one u for all: 5 % of the table's mean h
    relative_log,   // residual ln(h_fit/h)/0.05
};

std::string to_string(CfdForm form);
std::string to_string(CfdWeighting weighting);

struct CfdFormFit {
    CfdForm form = CfdForm::eq7_quarter;
    CfdWeighting weighting = CfdWeighting::absolute_5pct;
    double exponent = 0.25;
    double gamma_k_m3_kg = 0.0;        // coupling in N = dT + gamma dC, K m³/kg
    double gamma_se_k_m3_kg = 0.0;     // from (J'J)^-1, x sqrt(chi2/dof) when that exceeds 1
    double gamma_profile_lo_k_m3_kg = 0.0;  // profile interval: chi2(gamma) <= chi2_min + max(1, chi2/dof)
    double gamma_profile_hi_k_m3_kg = 0.0;
    double h0_w_m2k = 0.0;             // Eq. 7 diffusion floor; 0 and not fitted for the S8 shape
    double h0_se_w_m2k = 0.0;
    double b_w_m2k = 0.0;              // B (Eq. 7) or a (S8 shape), W/m²K per K^exponent
    double b_se_w_m2k = 0.0;
    double rmse_w_m2k = 0.0;           // sqrt(mean (h_fit - h)²)
    double rmse_pct = 0.0;             // sqrt(mean ((h_fit - h)/h)²) x 100, as the paper's 13.3 % for Eq. 8
    double chi2 = 0.0;                 // in the fit's own weighting
    int dof = 0;
    double chi2_per_dof = 0.0;
    bool converged = false;
    bool at_bound = false;             // a parameter ended on its search bound
};

// A fixed correlation evaluated on the same table (no parameter fitted).
struct CfdFixedModel {
    std::string label;
    double h0_w_m2k = 0.0, b_w_m2k = 0.0, gamma_k_m3_kg = 0.0, exponent = 0.25;
    double rmse_w_m2k = 0.0, rmse_pct = 0.0;
};

struct CfdGammaReport {
    int n_points = 0;
    std::vector<CfdFormFit> fits;      // form-major: Eq. 7 x 3 weightings, then S8 shape x 3
    // Combined gamma: unweighted mean of the fits' gammas;
    // u_combined = sqrt(mean within-fit variance + sample variance between fits).
    double gamma_combined_k_m3_kg = 0.0;
    double gamma_u_within_k_m3_kg = 0.0;   // sqrt(mean se²)
    double gamma_u_between_k_m3_kg = 0.0;  // sample standard deviation of the gammas (n - 1)
    double gamma_u_combined_k_m3_kg = 0.0;
    double gamma_min_k_m3_kg = 0.0, gamma_max_k_m3_kg = 0.0;
    // Theory: beta_C alpha/(beta_T D) (Eq. 6-7), mean over the table's film states, and the
    // paper's rounded 146 (Eq. 8).
    double gamma_theory_table_mean_k_m3_kg = 0.0;
    double gamma_theory_paper_k_m3_kg = 146.0;
    // beta_C/beta_T (no alpha/D): the gamma at which N = 0 is the density-neutral state of Eq. 2,
    // where B_net = 0 (Table S4's stagnation). Mean over the table's film states.
    double gamma_density_neutral_table_mean_k_m3_kg = 0.0;
    double z_vs_paper = 0.0;               // (combined - 146) / u_combined
    CfdFixedModel eq8;                     // Eq. 8: 0.3 + 1.25 |dT + 146 dC|^(1/4)
    CfdFixedModel eq_s8;                   // Eq. S8: 1.36 |dT|^0.3 (no humidity term)
    std::vector<CfdFormFit> eq7_gamma_146; // Eq. 7 with gamma fixed at 146, h0 and B free, per weighting
};

// Fits every form x weighting. Throws std::invalid_argument for fewer than 4 observations or a
// non-positive or non-finite h.
CfdGammaReport fit_cfd_gamma_forms(const std::vector<CfdHObservation>& observations);

}  // namespace manikind::analysis::reconcile
