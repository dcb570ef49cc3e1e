#include "analysis/reconcile/cfd_forms.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "analysis/reconcile/least_squares.hpp"
#include "physics/buoyancy.hpp"
#include "physics/psychrometrics.hpp"

namespace manikind::analysis::reconcile {
namespace {

constexpr double gamma_lo_k_m3_kg = 0.0;
constexpr double gamma_hi_k_m3_kg = 400.0;
constexpr double gamma_grid_step_k_m3_kg = 0.5;
constexpr double relative_u = 0.05;  // Methods: CFD h quasi-steady within 5 %

// dT and dC exactly as WholeBodyHModel (reconcile.cpp) builds them: wet skin, psychrometrics.hpp.
struct Drivers {
    std::vector<double> dt_c, dc_kg_m3, h_w_m2k;
};

Drivers drivers_of(const std::vector<CfdHObservation>& obs) {
    Drivers d;
    for (const auto& o : obs) {
        const double c_air_kg_m3 =
            physics::vapour_concentration_kg_m3(physics::vapour_pressure_pa(o.air_temp_c, o.air_rh_pct), o.air_temp_c);
        d.dt_c.push_back(o.skin_temp_c - o.air_temp_c);
        d.dc_kg_m3.push_back(physics::saturation_concentration_kg_m3(o.skin_temp_c) - c_air_kg_m3);
        d.h_w_m2k.push_back(o.h_w_m2k);
    }
    return d;
}

// Eq. 7 (exponent 1/4) or the Eq. S8 shape (exponent 0.3, h0 = 0).
double h_model_w_m2k(double h0_w_m2k, double b_w_m2k, double gamma_k_m3_kg, double exponent, double dt_c,
                     double dc_kg_m3) {
    return h0_w_m2k + b_w_m2k * std::pow(std::abs(dt_c + gamma_k_m3_kg * dc_kg_m3), exponent);
}

struct Params {
    double h0_w_m2k = 0.0, b_w_m2k = 0.0, gamma_k_m3_kg = 0.0;
};

std::vector<double> predictions(const Drivers& d, const Params& p, double exponent) {
    std::vector<double> out(d.h_w_m2k.size());
    for (std::size_t i = 0; i < out.size(); ++i)
        out[i] = h_model_w_m2k(p.h0_w_m2k, p.b_w_m2k, p.gamma_k_m3_kg, exponent, d.dt_c[i], d.dc_kg_m3[i]);
    return out;
}

std::vector<double> weighted_residuals(const Drivers& d, const std::vector<double>& h_fit, CfdWeighting w,
                                       double equal_u_w_m2k) {
    std::vector<double> r(h_fit.size());
    for (std::size_t i = 0; i < r.size(); ++i) {
        const double h = d.h_w_m2k[i];
        switch (w) {
            case CfdWeighting::absolute_5pct: r[i] = (h_fit[i] - h) / (relative_u * h); break;
            case CfdWeighting::equal: r[i] = (h_fit[i] - h) / equal_u_w_m2k; break;
            case CfdWeighting::relative_log:
                // A non-positive prediction is far from any CFD h: keep the residual finite and large.
                r[i] = std::log(std::max(h_fit[i], 1e-6) / h) / relative_u;
                break;
        }
    }
    return r;
}

void rmse_of(const Drivers& d, const std::vector<double>& h_fit, double& rmse_w_m2k, double& rmse_pct) {
    double s_abs = 0.0, s_rel = 0.0;
    for (std::size_t i = 0; i < h_fit.size(); ++i) {
        const double e = h_fit[i] - d.h_w_m2k[i];
        s_abs += e * e;
        s_rel += (e / d.h_w_m2k[i]) * (e / d.h_w_m2k[i]);
    }
    const auto n = static_cast<double>(h_fit.size());
    rmse_w_m2k = std::sqrt(s_abs / n);
    rmse_pct = 100.0 * std::sqrt(s_rel / n);
}

// Which parameters a fit frees; the vector passed to the least-squares routine is in this order.
struct Layout {
    bool h0_free = false, b_free = true, gamma_free = false;
};

Params unpack(const std::vector<double>& v, const Layout& l, const Params& fixed) {
    Params p = fixed;
    std::size_t k = 0;
    if (l.h0_free) p.h0_w_m2k = v[k++];
    if (l.b_free) p.b_w_m2k = v[k++];
    if (l.gamma_free) p.gamma_k_m3_kg = v[k++];
    return p;
}

struct Packed {
    std::vector<double> start;
    std::vector<Bounds> bounds;
};

Packed pack(const Params& p, const Layout& l) {
    Packed out;
    if (l.h0_free) {
        out.start.push_back(p.h0_w_m2k);
        out.bounds.push_back({-3.0, 3.0});
    }
    if (l.b_free) {
        out.start.push_back(p.b_w_m2k);
        out.bounds.push_back({0.0, 10.0});
    }
    if (l.gamma_free) {
        out.start.push_back(p.gamma_k_m3_kg);
        out.bounds.push_back({gamma_lo_k_m3_kg, gamma_hi_k_m3_kg});
    }
    return out;
}

struct OneFit {
    Params p;
    FitResult raw;
    Layout layout;
    std::vector<Bounds> bounds;
};

OneFit run_fit(const Drivers& d, CfdForm form, CfdWeighting w, double equal_u_w_m2k, const Params& start,
               const Layout& layout) {
    const double exponent = form == CfdForm::eq7_quarter ? 0.25 : 0.3;
    const Params fixed = start;
    const auto residuals = [&](const std::vector<double>& v) {
        return weighted_residuals(d, predictions(d, unpack(v, layout, fixed), exponent), w, equal_u_w_m2k);
    };
    Packed pk = pack(start, layout);
    OneFit out;
    out.raw = fit_weighted_least_squares(residuals, pk.start, pk.bounds, 200);
    out.p = unpack(out.raw.parameters, layout, fixed);
    out.layout = layout;
    out.bounds = pk.bounds;
    return out;
}

bool on_bound(const OneFit& f) {
    for (std::size_t k = 0; k < f.bounds.size(); ++k) {
        const double tol = 1e-6 * (f.bounds[k].hi - f.bounds[k].lo);
        if (f.raw.parameters[k] <= f.bounds[k].lo + tol || f.raw.parameters[k] >= f.bounds[k].hi - tol) return true;
    }
    return false;
}

CfdFormFit summarise(const Drivers& d, CfdForm form, CfdWeighting w, const OneFit& f) {
    CfdFormFit out;
    out.form = form;
    out.weighting = w;
    out.exponent = form == CfdForm::eq7_quarter ? 0.25 : 0.3;
    out.h0_w_m2k = f.p.h0_w_m2k;
    out.b_w_m2k = f.p.b_w_m2k;
    out.gamma_k_m3_kg = f.p.gamma_k_m3_kg;
    std::size_t k = 0;
    if (f.layout.h0_free) out.h0_se_w_m2k = f.raw.standard_errors[k++];
    if (f.layout.b_free) out.b_se_w_m2k = f.raw.standard_errors[k++];
    if (f.layout.gamma_free) out.gamma_se_k_m3_kg = f.raw.standard_errors[k++];
    out.chi2 = f.raw.chi2;
    out.dof = f.raw.n_points - static_cast<int>(f.raw.parameters.size());
    out.chi2_per_dof = out.chi2 / std::max(1, out.dof);
    out.converged = f.raw.converged;
    out.at_bound = on_bound(f);
    rmse_of(d, predictions(d, f.p, out.exponent), out.rmse_w_m2k, out.rmse_pct);
    return out;
}

// Three free parameters (Eq. 7) or two (S8 shape). The |N|^n kink at N = 0 gives chi2(gamma)
// several local minima, so gamma is first profiled on a grid (the other parameters refitted at
// each grid gamma), then all parameters are refined together from the best grid point. The same
// profile gives a Delta-chi2 interval beside the Jacobian standard error.
CfdFormFit fit_form(const Drivers& d, CfdForm form, CfdWeighting w, double equal_u_w_m2k) {
    const bool eq7 = form == CfdForm::eq7_quarter;
    const Layout nuisance{eq7, true, false};
    Params start{eq7 ? 0.3 : 0.0, eq7 ? 1.25 : 1.36, 0.0};
    std::vector<double> grid_gamma, grid_chi2;
    Params best_start = start;
    double best_chi2 = std::numeric_limits<double>::infinity();
    const auto n_grid = static_cast<int>(std::lround((gamma_hi_k_m3_kg - gamma_lo_k_m3_kg) / gamma_grid_step_k_m3_kg));
    for (int g = 0; g <= n_grid; ++g) {
        start.gamma_k_m3_kg = gamma_lo_k_m3_kg + gamma_grid_step_k_m3_kg * g;
        const OneFit f = run_fit(d, form, w, equal_u_w_m2k, start, nuisance);
        grid_gamma.push_back(start.gamma_k_m3_kg);
        grid_chi2.push_back(f.raw.chi2);
        if (f.raw.chi2 < best_chi2) {
            best_chi2 = f.raw.chi2;
            best_start = f.p;
        }
        start.h0_w_m2k = f.p.h0_w_m2k;  // warm start the next grid point
        start.b_w_m2k = f.p.b_w_m2k;
    }
    const OneFit full = run_fit(d, form, w, equal_u_w_m2k, best_start, Layout{eq7, true, true});
    CfdFormFit out = summarise(d, form, w, full);
    // Profile interval: chi2_profile(gamma) <= chi2_min + max(1, chi2_min/dof) (Birge-scaled Delta chi2 = 1).
    const double chi2_min = std::min(out.chi2, best_chi2);
    const double threshold = chi2_min + std::max(1.0, chi2_min / std::max(1, out.dof));
    std::size_t i_best = 0;
    for (std::size_t i = 1; i < grid_chi2.size(); ++i)
        if (grid_chi2[i] < grid_chi2[i_best]) i_best = i;
    const auto crossing = [&](std::size_t inside, std::size_t outside) {
        const double c_in = grid_chi2[inside], c_out = grid_chi2[outside];
        const double t = c_out > c_in ? (threshold - c_in) / (c_out - c_in) : 0.0;
        return grid_gamma[inside] + std::clamp(t, 0.0, 1.0) * (grid_gamma[outside] - grid_gamma[inside]);
    };
    std::size_t lo = i_best, hi = i_best;
    while (lo > 0 && grid_chi2[lo - 1] <= threshold) --lo;
    while (hi + 1 < grid_chi2.size() && grid_chi2[hi + 1] <= threshold) ++hi;
    out.gamma_profile_lo_k_m3_kg = lo > 0 ? crossing(lo, lo - 1) : grid_gamma.front();
    out.gamma_profile_hi_k_m3_kg = hi + 1 < grid_chi2.size() ? crossing(hi, hi + 1) : grid_gamma.back();
    return out;
}

CfdFixedModel fixed_model(const Drivers& d, std::string label, const Params& p, double exponent) {
    CfdFixedModel m;
    m.label = std::move(label);
    m.h0_w_m2k = p.h0_w_m2k;
    m.b_w_m2k = p.b_w_m2k;
    m.gamma_k_m3_kg = p.gamma_k_m3_kg;
    m.exponent = exponent;
    rmse_of(d, predictions(d, p, exponent), m.rmse_w_m2k, m.rmse_pct);
    return m;
}

}  // namespace

std::string to_string(CfdForm form) {
    switch (form) {
        case CfdForm::eq7_quarter: return "Eq. 7: h0 + B |dT + gamma dC|^(1/4)";
        case CfdForm::s8_power_0_3: return "Eq. S8 shape: a |dT + gamma dC|^0.3";
    }
    return "?";
}

std::string to_string(CfdWeighting weighting) {
    switch (weighting) {
        case CfdWeighting::absolute_5pct: return "absolute, u = 5 % of h";
        case CfdWeighting::equal: return "equal, u = 5 % of mean h";
        case CfdWeighting::relative_log: return "log residuals, u = 5 %";
    }
    return "?";
}

CfdGammaReport fit_cfd_gamma_forms(const std::vector<CfdHObservation>& observations) {
    if (observations.size() < 4) throw std::invalid_argument("fit_cfd_gamma_forms: need at least 4 observations");
    double mean_h_w_m2k = 0.0;
    for (const auto& o : observations) {
        if (!std::isfinite(o.h_w_m2k) || o.h_w_m2k <= 0.0)
            throw std::invalid_argument("fit_cfd_gamma_forms: case " + std::to_string(o.case_id) +
                                        " has a non-positive or non-finite h");
        mean_h_w_m2k += o.h_w_m2k;
    }
    mean_h_w_m2k /= static_cast<double>(observations.size());
    const double equal_u_w_m2k = relative_u * mean_h_w_m2k;
    const Drivers d = drivers_of(observations);

    CfdGammaReport rep;
    rep.n_points = static_cast<int>(observations.size());
    const CfdWeighting weightings[] = {CfdWeighting::absolute_5pct, CfdWeighting::equal, CfdWeighting::relative_log};
    for (const CfdForm form : {CfdForm::eq7_quarter, CfdForm::s8_power_0_3})
        for (const CfdWeighting w : weightings) rep.fits.push_back(fit_form(d, form, w, equal_u_w_m2k));

    // Combined gamma: mean over fits; u² = mean within-fit variance + sample variance between fits.
    const auto n_fits = static_cast<double>(rep.fits.size());
    double sum = 0.0, sum_var = 0.0;
    rep.gamma_min_k_m3_kg = std::numeric_limits<double>::infinity();
    rep.gamma_max_k_m3_kg = -std::numeric_limits<double>::infinity();
    for (const auto& f : rep.fits) {
        sum += f.gamma_k_m3_kg;
        sum_var += f.gamma_se_k_m3_kg * f.gamma_se_k_m3_kg;
        rep.gamma_min_k_m3_kg = std::min(rep.gamma_min_k_m3_kg, f.gamma_k_m3_kg);
        rep.gamma_max_k_m3_kg = std::max(rep.gamma_max_k_m3_kg, f.gamma_k_m3_kg);
    }
    rep.gamma_combined_k_m3_kg = sum / n_fits;
    double ss = 0.0;
    for (const auto& f : rep.fits) ss += (f.gamma_k_m3_kg - rep.gamma_combined_k_m3_kg) * (f.gamma_k_m3_kg - rep.gamma_combined_k_m3_kg);
    rep.gamma_u_within_k_m3_kg = std::sqrt(sum_var / n_fits);
    rep.gamma_u_between_k_m3_kg = std::sqrt(ss / (n_fits - 1.0));
    rep.gamma_u_combined_k_m3_kg = std::sqrt(sum_var / n_fits + ss / (n_fits - 1.0));

    // Theory (Eq. 6-7): beta_C alpha/(beta_T D) at each case's film state, averaged.
    double theory_sum = 0.0, density_sum = 0.0;
    for (const auto& o : observations) {
        physics::SkinAirState s;
        s.skin_temp_c = o.skin_temp_c;
        s.air_temp_c = o.air_temp_c;
        s.air_rh_pct = o.air_rh_pct;
        s.skin_wettedness = 1.0;
        const physics::BuoyancyResult b = physics::buoyancy(s);
        theory_sum += b.coupling_coefficient;
        density_sum += b.beta_c_m3_kg / b.beta_t_1_k;
    }
    rep.gamma_theory_table_mean_k_m3_kg = theory_sum / static_cast<double>(observations.size());
    rep.gamma_density_neutral_table_mean_k_m3_kg = density_sum / static_cast<double>(observations.size());
    rep.z_vs_paper = (rep.gamma_combined_k_m3_kg - rep.gamma_theory_paper_k_m3_kg) / rep.gamma_u_combined_k_m3_kg;

    rep.eq8 = fixed_model(d, "Eq. 8: 0.3 + 1.25 |dT + 146 dC|^(1/4)", Params{0.3, 1.25, 146.0}, 0.25);
    rep.eq_s8 = fixed_model(d, "Eq. S8: 1.36 |dT|^0.3", Params{0.0, 1.36, 0.0}, 0.3);
    for (const CfdWeighting w : weightings) {
        const OneFit f = run_fit(d, CfdForm::eq7_quarter, w, equal_u_w_m2k, Params{0.3, 1.25, 146.0},
                                 Layout{true, true, false});
        rep.eq7_gamma_146.push_back(summarise(d, CfdForm::eq7_quarter, w, f));
    }
    return rep;
}

}  // namespace manikind::analysis::reconcile
