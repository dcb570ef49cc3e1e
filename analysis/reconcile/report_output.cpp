#include "analysis/reconcile/report_output.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

#include <fmt/core.h>

#include "analysis/plot/body_map.hpp"
#include "analysis/plot/svg_figure.hpp"

namespace manikind::analysis::reconcile {
namespace {

nlohmann::json stats_json(const FitStats& s) {
    return {{"rmse_w_m2", s.rmse}, {"chi2_per_dof", s.chi2_per_dof}, {"outside_ci", s.outside_ci}, {"n_points", s.n_points}};
}

nlohmann::json candidate_json(const CandidateResult& c) {
    nlohmann::json params = nlohmann::json::object(), params_u = nlohmann::json::object();
    for (std::size_t i = 0; i < c.values.size(); ++i) {
        params[c.parameter_names[i]] = c.values[i];
        params_u[c.parameter_names[i]] = std::isfinite(c.uncertainties[i]) ? nlohmann::json(c.uncertainties[i]) : nlohmann::json();
    }
    nlohmann::json interval = nlohmann::json::object();
    for (std::size_t i = 0; i < c.values.size() && i < c.interval_lo.size(); ++i)
        interval[c.parameter_names[i]] = std::isfinite(c.interval_lo[i]) && std::isfinite(c.interval_hi[i])
                                             ? nlohmann::json::array({c.interval_lo[i], c.interval_hi[i]})
                                             : nlohmann::json();
    nlohmann::json j = {{"term", c.label}, {"parameters", params}, {"parameter_u", params_u},
                        {"interval_95", interval}, {"evidence_chi2", c.evidence}, {"chi2", c.chi2},
                        {"delta_bic", c.delta_bic}, {"after", stats_json(c.after)},
                        {"accepted", c.accepted}, {"reason", c.reason}, {"advice", c.advice}};
    j["loo_rmse_w_m2"] = c.loo_rmse ? nlohmann::json(*c.loo_rmse) : nlohmann::json();
    j["loo_chi2"] = c.loo_score ? nlohmann::json(*c.loo_score) : nlohmann::json();
    return j;
}

// The unit of each driver reconcile correlates residuals with (forward_models.cpp), for the axis.
std::string driver_axis_label(const std::string& driver) {
    static const std::map<std::string, std::string, std::less<>> units{
        {"skin-air temperature difference", "K"}, {"wall-air temperature difference", "K"},
        {"vapour concentration difference", "kg/m³"}, {"relative humidity", "%"}, {"air speed", "m/s"},
        {"wettedness", "0-1"}, {"zone height", "m"}, {"facing (back -1, front +1)", "-1, 0, +1"}};
    const auto it = units.find(driver);
    return it == units.end() ? driver : driver + " (" + it->second + ")";
}

}  // namespace

nlohmann::json report_to_json(const Report& r, const ForwardModel& model) {
    nlohmann::json j;
    j["twin"] = r.twin_name;
    j["before"] = stats_json(r.before);
    j["consistent_before"] = r.consistent_before;
    // Not judged on a lower-bound noise (one replicate, nothing carried): null, with the reason.
    j["gof_p_before"] = r.noise_lower_bound ? nlohmann::json() : nlohmann::json(r.gof_p_before);
    j["not_judged"] = r.noise_lower_bound
                          ? nlohmann::json("goodness of fit, locating and candidates' uncertainties: one replicate per case "
                                           "and no scatter carried (--noise-from), so the noise is only a lower bound")
                          : nlohmann::json();
    const auto& n = r.noise;
    nlohmann::json zone_sd = nlohmann::json::object();
    for (const auto& [zone, sd] : n.zone_sd_w_m2) zone_sd[std::to_string(zone)] = sd;
    j["noise_model"] = {{"from_replicates", n.from_replicates}, {"carried_from", n.carried_from}, {"random_dof", n.random_dof},
                        {"scatter_steps", n.scatter_steps},
                        {"scatter_converged", n.scatter_converged ? nlohmann::json(*n.scatter_converged) : nlohmann::json()},
                        {"relative_sd", n.relative_sd}, {"zone_sd_w_m2", zone_sd}, {"zone_sd_prior_dof", n.zone_prior_dof}, {"trial_factor_sd", n.trial_factor_sd},
                        {"calibration_offset_u_w_m2", n.calibration_offset_u_w_m2},
                        {"calibration_gain_u", n.calibration_gain_u}, {"air_temp_u_c", n.air_temp_u_c},
                        {"wall_temp_u_c", n.wall_temp_u_c}, {"probe_shared_fraction", n.probe_shared_fraction}, {"rh_u", n.rh_u_text}, {"notes", n.notes}};
    // Infinite when no claim can be made (one replicate, nothing carried): null in JSON.
    j["claim_rule"] = {{"alpha", r.alpha}, {"family_wise", true}, {"null_simulations", r.null_simulations},
                       {"covariance_draws", r.covariance_draws},
                       {"null_threshold_chi2", std::isfinite(r.null_threshold) ? nlohmann::json(r.null_threshold) : nlohmann::json()},
                       {"family_evidence", r.family_evidence}, {"null_p", r.null_p}};
    j["anomalies"] = nlohmann::json::array();
    for (const auto& a : r.anomalies)
        j["anomalies"].push_back({{"zone", a.zone}, {"zone_name", a.zone_name}, {"kind", a.kind}, {"value", a.value},
                                  {"u", a.u}, {"unit", a.kind == "gain" ? "1" : "W/m2"}, {"offset_w_m2", a.offset_w_m2},
                                  {"u_w_m2", a.u_w_m2}, {"z", a.z}, {"cases_outside_ci", a.cases_outside}, {"cases", a.cases}});
    j["ambiguous_with"] = r.ambiguous_with;
    j["untold_partners"] = r.untold_partners;
    j["located"] = nlohmann::json::array();
    if (!r.noise_lower_bound)
        for (const auto& l : r.located) j["located"].push_back({{"where", l.where}, {"driver", l.driver}, {"strength", l.strength}});
    if (r.explanation) {
        auto e = candidate_json(*r.explanation);
        e["statement"] = r.statement;
        e["partial"] = r.explanation_partial;
        e["gof_p_after"] = r.gof_p_after;
        // The terms in the order claimed, each step's evidence against its own null and the fit after it.
        e["steps"] = nlohmann::json::array();
        for (const auto& st : r.steps)
            e["steps"].push_back({{"label", st.label}, {"evidence", st.evidence}, {"threshold", st.threshold},
                                  {"chi2_after", st.chi2_after}, {"gof_p_after", st.gof_p_after}, {"partial", st.partial}});
        j["explanation"] = e;
    } else {
        j["explanation"] = nullptr;
    }
    j["statement"] = r.statement;
    j["measurement"] = r.measurement;
    if (r.remainder.empty()) {
        j["remainder"] = nullptr;
    } else {
        nlohmann::json located = nlohmann::json::array();
        for (const auto& l : r.remainder_located) located.push_back({{"where", l.where}, {"driver", l.driver}, {"strength", l.strength}});
        j["remainder"] = {{"statement", r.remainder}, {"located", located}};
    }
    j["candidates"] = nlohmann::json::array();
    for (const auto& c : r.candidates) {
        auto cj = candidate_json(c);
        if (r.noise_lower_bound)
            for (auto& [name, u] : cj["parameter_u"].items()) {
                (void)name;
                u = nullptr;
            }
        j["candidates"].push_back(std::move(cj));
    }
    j["after"] = stats_json(r.after);
    j["by_region"] = nlohmann::json::array();
    for (const auto& b : r.by_region)
        j["by_region"].push_back({{"region", b.region}, {"before", stats_json(b.before)}, {"after", stats_json(b.after)}});
    j["by_case"] = nlohmann::json::array();
    for (const auto& [id, b] : r.by_case)
        j["by_case"].push_back({{"case", id}, {"before", stats_json(b.before)}, {"after", stats_json(b.after)}});
    nlohmann::json terms = nlohmann::json::array();
    for (const auto& t : r.new_version.terms) terms.push_back({{"name", t.name}, {"parameters", t.parameters}, {"region", t.region}, {"zones", t.zones}});
    j["new_twin_version"] = {{"name", r.new_version.name}, {"terms", terms}};
    nlohmann::json points = nlohmann::json::array();
    const auto& pts = model.points();
    for (std::size_t i = 0; i < pts.size(); ++i)
        points.push_back({{"case", pts[i].case_id}, {"zone", pts[i].zone}, {"region", pts[i].region},
                          {"q_exp_w_m2", pts[i].q_exp}, {"U_w_m2", pts[i].expanded_u},
                          {"q_sim_before_w_m2", r.predicted_before[i]}, {"q_sim_after_w_m2", r.predicted_after[i]},
                          {"z_before", (pts[i].q_exp - r.predicted_before[i]) / pts[i].expanded_u}});
    j["points"] = points;
    return j;
}

nlohmann::json power_to_json(const PowerReport& plan) {
    nlohmann::json j = {{"alpha", plan.alpha}, {"power", 0.8}, {"campaign_replicates", plan.campaign_replicates},
                        {"replicates", plan.replicates}};
    j["claim_threshold"] = nlohmann::json::object();
    for (const auto& [n, t] : plan.claim_threshold) j["claim_threshold"][std::to_string(n)] = t;
    j["limits"] = nlohmann::json::array();
    for (const auto& d : plan.limits)
        j["limits"].push_back({{"term", d.label}, {"parameter", d.parameter}, {"unit", d.unit}, {"null", d.null_value},
                               {"replicates", d.replicates}, {"smallest_effect", d.value ? nlohmann::json(*d.value) : nlohmann::json()},
                               {"method", d.method},
                               {"simulated_power", d.method == "scaled" ? nlohmann::json() : nlohmann::json(d.simulated_power)},
                               {"campaigns", d.campaigns},
                               {"non_monotone_labs", d.non_monotone_labs ? nlohmann::json(*d.non_monotone_labs) : nlohmann::json()},
                               {"tried", [&] {
                                    nlohmann::json t = nlohmann::json::array();
                                    for (const auto& pt : d.tried)
                                        t.push_back({{"value", pt.value}, {"named", pt.named}, {"named_alone", pt.named_alone}, {"campaigns", pt.campaigns},
                                                   {"reconciled", pt.reconciled}});
                                    return t;
                                }()},
                               {"calibration", [&] {
                                    nlohmann::json t = nlohmann::json::array();
                                    for (const auto& c : d.calibration)
                                        t.push_back({{"channel", c.channel}, {"limit", c.limit}, {"rank_correlation", c.rank_correlation},
                                                     {"p_value", c.p_value}, {"flagged", c.flagged}, {"value", c.value},
                                                     {"within_half_limit", {{"named", c.within_named}, {"campaigns", c.within}}},
                                                     {"beyond_half_limit", {{"named", c.beyond_named}, {"campaigns", c.beyond}}},
                                                     {"smallest_effect_within_half_limit", c.limit_within ? nlohmann::json(*c.limit_within) : nlohmann::json()},
                                                     {"at_most", c.limit_within_at_most}});
                                    return t;
                                }()}});
    return j;
}

std::string power_to_text(const PowerReport& plan) {
    std::ostringstream o;
    o << fmt::format("Smallest effect named with 80 % power (false claims at most {:.0f} %), by replicates per case:\n",
                     100.0 * plan.alpha);
    o << fmt::format("  {:<30} {:<10} {:>6}", "term", "parameter", "null");
    for (int n : plan.replicates) o << fmt::format(" {:>12}", fmt::format("n = {}{}", n, n == plan.campaign_replicates ? "*" : ""));
    o << "\n";
    std::vector<std::string> labels;
    for (const auto& d : plan.limits)
        if (std::find(labels.begin(), labels.end(), d.label) == labels.end()) labels.push_back(d.label);
    for (const auto& label : labels) {
        std::string row;
        for (int n : plan.replicates)
            for (const auto& d : plan.limits)
                if (d.label == label && d.replicates == n) {
                    if (row.empty()) row = fmt::format("  {:<30} {:<10} {:>6g}", label, d.parameter + (d.unit.empty() ? "" : ""), d.null_value);
                    row += fmt::format(" {:>12}", d.value ? fmt::format("{:.3g}", *d.value) : std::string("not reached"));
                }
        o << row << "\n";
    }
    int campaigns = 0;
    for (const auto& d : plan.limits)
        if (!d.tried.empty()) campaigns = std::max(campaigns, d.tried.front().campaigns);
    o << "  * this campaign's replicates. Units: gamma K m3/kg, h0 W/m2K, delta_c and bias_c degC, r_m2k_w m2K/W;\n"
         "    fraction: the wet fraction below which a region's dryness is found.\n";
    if (campaigns > 0)
        o << fmt::format("    At n = {0}: each value tried was checked by running reconcile itself on {1} campaigns of this\n"
                         "    design drawn anew with the effect concealed (conditions landing anew, probes and the manikin's\n"
                         "    calibration off within their specifications, trials scattering as this campaign's do). Named: the\n"
                         "    term alone, or beside a drawn probe's own calibration error (the air bias, the wall), found within\n"
                         "    its interval. The value printed is where the share named crosses 80 % between two values tried.\n"
                         "    Other n: a fast model, scaled per term by how far the whole decision moved it at n = {0}\n"
                         "    (docs/reconcile.md).\n"
                         "    How far to trust it: on campaigns from the project's generator, 100 per term, limits printed this\n"
                         "    way were named in 71-85 %, pooled 78 %, in labs that set their chamber by their own probes (the\n"
                         "    labs the planner draws); in labs whose air sits exactly at the case's values, 65-82 % (gamma 97 %).\n"
                         "    One plan is conditional on this campaign's own noise estimate and air probe (docs/reconcile.md,\n"
                         "    \"Detection limits\").\n",
                         plan.campaign_replicates, campaigns);
    if (campaigns > 0) {
        // Which limits hang on how far a probe (or the manikin's calibration) erred within its spec.
        auto describe = [](const CalibrationSensitivity& c) -> std::pair<std::string, std::string> {
            if (c.channel == "air_temp_c") return {"air probe", fmt::format("±{:.2g} °C", c.limit / 2)};
            if (c.channel == "air_rh_pct") return {"humidity probe", fmt::format("±{:.2g} % RH", c.limit / 2)};
            if (c.channel == "wall_temp_c") return {"wall probe", fmt::format("±{:.2g} °C", c.limit / 2)};
            if (c.channel == "heat_flux_offset") return {"manikin's flux offset", fmt::format("±{:.2g} W/m²", c.limit / 2)};
            if (c.channel == "heat_flux_gain") return {"manikin's flux gain", fmt::format("±{:.2g} %", 100.0 * c.limit / 2)};
            return {c.channel, fmt::format("±{:.2g}", c.limit / 2)};
        };
        int tested = 0;
        std::string lines;
        for (const auto& d : plan.limits)
            for (const auto& c : d.calibration) {
                ++tested;
                if (!c.flagged) continue;
                const auto [what, half] = describe(c);
                lines += fmt::format(
                    "  {}: the {}'s calibration (rank correlation {:.2f}, p {:.2g}). At {:.3g} named in {} of {}\n"
                    "    drawn labs whose {} erred within {} (half its limit), {} of {} beyond.\n"
                    "    With the {} calibrated to {}: {}.\n",
                    d.label, what, c.rank_correlation, c.p_value, c.value, c.within_named, c.within, what, half, c.beyond_named, c.beyond, what,
                    half,
                    c.limit_within ? fmt::format("{}{:.3g}", c.limit_within_at_most ? "at most " : "", *c.limit_within)
                                   : std::string("not reached at the values tried"));
            }
        if (tested > 0)
            o << (lines.empty() ? "Calibration: no limit here hangs on how far a probe or the manikin's calibration erred within its\n"
                                  "    spec (each term's drawn labs split by that error; 5 % over the term's calibrations).\n"
                                : "Calibration: limits that hang on how far a probe or the manikin's calibration erred within its\n"
                                  "    spec (each term's drawn labs split by that error; 5 % over the term's calibrations):\n" + lines);
    } else
        o << "    A fast model of the decision only (no replicate scatter to draw campaigns from, or --power-campaigns 0):\n"
             "    optimistic where terms share evidence; read the limits as lower bounds (docs/reconcile.md).\n";
    return o.str();
}

std::string report_to_text(const Report& r) {
    std::ostringstream o;
    auto stats_line = [](const FitStats& s) {
        return fmt::format("RMSE {:7.2f}   chi2/dof {:8.2f}   outside 95 % CI {:4d} of {}", s.rmse, s.chi2_per_dof, s.outside_ci, s.n_points);
    };
    o << "Twin: " << r.twin_name << "\n";
    // The answer first; the evidence behind it follows.
    o << (r.explanation ? "Explanation: " + r.explanation->label : std::string("Explanation: none")) << "\n  " << r.statement << "\n";
    if (r.steps.size() > 1 || r.explanation_partial) {
        o << "  Claimed in steps (each against the null of the twin with the steps before it held):\n";
        for (std::size_t i = 0; i < r.steps.size(); ++i)
            o << fmt::format("    {}. {}: evidence {:.1f} beyond {:.1f}; fit after it p = {:.2g}{}\n", i + 1, r.steps[i].label,
                             r.steps[i].evidence, r.steps[i].threshold, r.steps[i].gof_p_after,
                             r.steps[i].partial ? " (still beyond the noise)" : "");
    }
    for (const auto& m : r.measurement) o << "  Measurement: " << m << "\n";
    o << "\n";
    o << "Before: " << stats_line(r.before)
      << (r.noise_lower_bound ? "   (against each point's own U: a lower bound, not a verdict)" : "") << "\n";
    const auto& n = r.noise;
    std::string factors;
    for (const auto& [name, sd] : n.trial_factor_sd) factors += fmt::format("{}{} {:.3g}", factors.empty() ? "" : ", ", name, sd);
    o << fmt::format("Noise:  {}; calibration ±{:.2f} W/m² + {:.1f} % shared by all points; probes' Type B "
                     "±{:.2f} °C air, RH {}, ±{:.2f} °C wall ({:.0f} % of that variance common to all cases, the rest "
                     "per case)\n",
                     n.from_replicates || !n.carried_from.empty()
                         ? fmt::format("replicate scatter pooled per zone ({} dof{}), {:.1f} % of flux; per trial shared: {}",
                                       n.random_dof, n.carried_from.empty() ? "" : ", carried from " + n.carried_from,
                                       100.0 * n.relative_sd, factors)
                         : std::string("no replicates to pool"),
                     n.calibration_offset_u_w_m2, 100.0 * n.calibration_gain_u, n.air_temp_u_c, n.rh_u_text.empty() ? "-" : n.rh_u_text,
                     n.wall_temp_u_c, 100.0 * n.probe_shared_fraction);
    for (const auto& note : n.notes) o << "        " << note << "\n";
    if (std::isfinite(r.null_threshold))
        o << fmt::format("Claim:  evidence (chi2 drop) of any term or zone beyond {:.1f}, what noise alone exceeds in {:.0f} % of "
                         "{} simulated campaigns ({}); observed best {:.1f} under the first noise model, p {}\n\n",
                         r.null_threshold, 100.0 * r.alpha, r.null_simulations,
                         r.covariance_draws > 0 ? fmt::format("judged by {} re-estimations of the noise model", r.covariance_draws)
                                                : std::string("the noise model taken as exact"),
                         r.family_evidence,
                         r.null_p * static_cast<double>(r.null_simulations + 1) <= 1.0 + 1e-9
                             ? fmt::format("< {:.2g}", 1.0 / static_cast<double>(r.null_simulations))
                             : fmt::format("= {:.3f}", r.null_p));
    else
        o << "Claim:  none possible (one replicate per case, no scatter carried: --noise-from)\n\n";
    o << "Located:\n";
    if (r.noise_lower_bound)
        o << "  not judged: on one replicate per case the noise is a lower bound, and where the twin departs from it\n"
             "  is noise as often as physics (two replicates of a few cases, or --noise-from, let it be judged)\n";
    else
        for (const auto& l : r.located) o << fmt::format("  {}  (driver: {}, |r| = {:.2f})\n", l.where, l.driver, l.strength);
    o << "\nCandidates (best first):\n";
    o << fmt::format("  {:<44} {:>9} {:>9} {:>9}  {}\n",
                     r.noise_lower_bound ? "term (best fit; ± not judged)" : "term (± standard uncertainty)", "evidence",
                     "LOO RMSE", "chi2/dof", "verdict");
    for (std::size_t i = 0; i < r.candidates.size() && i < 12; ++i) {
        const auto& c = r.candidates[i];
        std::string params;
        for (std::size_t k = 0; k < c.values.size(); ++k)
            params += r.noise_lower_bound ? fmt::format(" {}={:.4g}", c.parameter_names[k], c.values[k])
                                          : fmt::format(" {}={:.4g}±{:.2g}", c.parameter_names[k], c.values[k], c.uncertainties[k]);
        o << fmt::format("  {:<44} {:>9.1f} {:>9} {:>9.2f}  {}\n", c.label + params, c.evidence,
                         c.loo_rmse ? fmt::format("{:.2f}", *c.loo_rmse) : "-", c.after.chi2_per_dof, c.reason);
    }
    if (r.candidates.size() > 12) o << fmt::format("  ... and {} more (--json lists all)\n", r.candidates.size() - 12);
    o << "\nAfter:  " << stats_line(r.after) << "\n\nBy case (RMSE before -> after, outside CI before -> after):\n";
    for (const auto& [id, b] : r.by_case)
        o << fmt::format("  case {:<9d} {:7.2f} -> {:7.2f}   {:3d} -> {:3d} of {}\n", id, b.before.rmse, b.after.rmse,
                         b.before.outside_ci, b.after.outside_ci, b.before.n_points);
    o << "\nBy region (RMSE before -> after, outside CI before -> after):\n";
    for (const auto& b : r.by_region)
        o << fmt::format("  {:<14} {:7.2f} -> {:7.2f}   {:3d} -> {:3d} of {}\n", b.region, b.before.rmse, b.after.rmse,
                         b.before.outside_ci, b.after.outside_ci, b.before.n_points);
    return o.str();
}

std::vector<std::string> plot_file_names() {
    return {"parity.svg", "residual_vs_driver.svg", "residual_body_map.svg", "residual_vs_height.svg"};
}

namespace {

// A point's residual in units of its noise: the diagonal of the covariance the fits were judged
// against (replicate scatter and the instruments' Type B), or the recording's own u without one.
double standardised(const Report& r, const Point& p, std::size_t i, double predicted) {
    const bool have = r.noise.covariance.rows() > static_cast<Eigen::Index>(i);
    const double var = have ? r.noise.covariance(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(i)) : 0.0;
    const double sd = var > 0.0 ? std::sqrt(var) : p.standard_u();
    return sd > 0.0 ? (p.q_exp - predicted) / sd : 0.0;
}

// What the "after" of the plots holds: the terms claimed, in the order claimed.
std::string after_caption(const Report& r) {
    if (!r.explanation) return "";
    std::string terms;
    for (const auto& st : r.steps) terms += (terms.empty() ? "" : " + ") + st.label;
    return "after: + " + (terms.empty() ? r.explanation->label : terms);
}

}  // namespace

std::vector<std::filesystem::path> write_plots(const Report& r, const ForwardModel& model, const std::filesystem::path& dir,
                                               const std::string& unit) {
    namespace pl = plot;
    std::filesystem::create_directories(dir);
    const auto& pts = model.points();
    const char* before_colour = "#d62728";
    const char* after_colour = "#1f77b4";

    // Parity (the paper's Fig. 1D): x = Q_exp with its 95 % interval, y = Q_sim, and the 1:1 line.
    pl::Figure parity;
    parity.width_px = 600;
    parity.height_px = 630;
    parity.title = "Twin vs recordings";
    parity.notes.push_back("bars: the recording's 95 % interval (± U); dashed: 1:1");
    pl::XYPanel pp;
    pp.box = {0, 46, 600, 584};
    pp.x.label = "Measured Q_exp (" + unit + ")";
    pp.y.label = "Twin Q_sim (" + unit + ")";
    pp.identity_line = true;
    pl::Series before, after;
    before.label = fmt::format("before: {} (RMSE {:.2f} {})", r.twin_name, r.before.rmse, unit);
    before.colour = before_colour;
    if (r.explanation) after.label = fmt::format("after: + {} (RMSE {:.2f} {})", r.explanation->label, r.after.rmse, unit);
    after.colour = after_colour;
    for (auto* s : {&before, &after}) {
        s->marker_radius_px = 2.6;
        s->opacity = 0.75;
    }
    for (std::size_t i = 0; i < pts.size(); ++i) {
        before.x.push_back(pts[i].q_exp);
        before.x_err.push_back(pts[i].expanded_u);
        before.y.push_back(r.predicted_before[i]);
        if (r.explanation) {
            after.x.push_back(pts[i].q_exp);
            after.x_err.push_back(pts[i].expanded_u);
            after.y.push_back(r.predicted_after[i]);
        }
    }
    pp.series.push_back(before);
    if (r.explanation) pp.series.push_back(after);
    parity.xy_panels.push_back(std::move(pp));
    const auto parity_path = dir / plot_file_names()[0];
    pl::write_svg(parity, parity_path);
    std::vector<std::filesystem::path> written{parity_path};

    // Residual vs the strongest driver, with the recording's 95 % interval as the bar.
    pl::Series res_before, res_after;
    res_before.label = "before";
    res_before.colour = before_colour;
    res_after.label = "after";
    res_after.colour = after_colour;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const auto it = pts[i].drivers.find(r.best_driver);
        if (it == pts[i].drivers.end()) continue;
        res_before.x.push_back(it->second);
        res_before.y.push_back(pts[i].q_exp - r.predicted_before[i]);
        res_before.y_err.push_back(pts[i].expanded_u);
        res_after.x.push_back(it->second);
        res_after.y.push_back(pts[i].q_exp - r.predicted_after[i]);
    }
    if (res_before.x.empty()) return written;
    for (auto* s : {&res_before, &res_after}) {
        s->marker_radius_px = 2.6;
        s->opacity = 0.75;
    }
    pl::Figure residual;
    residual.width_px = 640;
    residual.height_px = 520;
    residual.title = "Residual vs " + r.best_driver;
    residual.notes.push_back("bars: the recording's 95 % interval (± U)");
    pl::XYPanel rp;
    rp.box = {0, 46, 640, 474};
    rp.x.label = driver_axis_label(r.best_driver);
    rp.y.label = "Q_exp − Q_sim (" + unit + ")";
    rp.reference_lines.push_back({true, 0.0, "#888888", ""});
    rp.series.push_back(res_before);
    if (r.explanation) rp.series.push_back(res_after);
    residual.xy_panels.push_back(std::move(rp));
    const auto res_path = dir / plot_file_names()[1];
    pl::write_svg(residual, res_path);
    written.push_back(res_path);

    // The body map (issue 61 part 3): each zone's standardised residual, averaged over the cases,
    // front and back, before and after. Red: the recording above the twin; blue: below.
    std::map<std::string, std::pair<double, int>> z_before, z_after;
    std::map<std::string, std::string> region_of;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        if (pts[i].zone == 0 || pts[i].zone_name.empty()) continue;
        region_of[pts[i].zone_name] = pts[i].region;
        auto& b = z_before[pts[i].zone_name];
        b.first += standardised(r, pts[i], i, r.predicted_before[i]);
        ++b.second;
        if (r.explanation) {
            auto& a = z_after[pts[i].zone_name];
            a.first += standardised(r, pts[i], i, r.predicted_after[i]);
            ++a.second;
        }
    }
    if (!z_before.empty()) {
        pl::BodyMap body;
        body.title = "Where the twin misses: mean standardised residual by zone";
        body.scale_label = "(Q_exp − Q_sim)/σ";
        body.scale_min = -3.0;
        body.scale_max = 3.0;
        body.colour = [](double v) { return pl::diverging_colour(v, 3.0); };
        auto panel_of = [](const std::map<std::string, std::pair<double, int>>& sums, std::string caption) {
            pl::BodyMapPanel panel;
            panel.caption = std::move(caption);
            for (const auto& [zone, s] : sums) panel.value_by_zone[zone] = s.first / s.second;
            return panel;
        };
        body.panels.push_back(panel_of(z_before, "before: " + r.twin_name));
        if (r.explanation) body.panels.push_back(panel_of(z_after, after_caption(r)));
        body.tooltip = [&z_before, &region_of](const std::string& zone, std::optional<double> v) {
            const auto n = z_before.find(zone);
            return v ? fmt::format("{} ({}): {:+.2f} σ, mean of {} case{}", zone, region_of[zone], *v, n->second.second,
                                   n->second.second == 1 ? "" : "s")
                     : zone + ": not in this campaign";
        };
        body.notes.push_back("σ: each point's noise (replicate scatter and the instruments' Type B); red: the recording above the twin;");
        body.notes.push_back("grey: a zone without points; the scale is clamped at ±3 σ (the tooltip gives the value).");
        const auto body_path = dir / plot_file_names()[2];
        std::ofstream out(body_path, std::ios::binary);
        out << pl::body_map_svg(body);
        if (!out) throw std::runtime_error("cannot write " + body_path.string());
        written.push_back(body_path);
    }

    // Residual against each zone's height (the probe's 1.1 m marked): a vertical gradient shows
    // as a slope, a local effect as a cluster at its height.
    pl::Series h_before, h_after;
    h_before.label = "before";
    h_before.colour = before_colour;
    h_after.label = after_caption(r);
    h_after.colour = after_colour;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const auto it = pts[i].drivers.find("zone height");
        if (it == pts[i].drivers.end()) continue;
        h_before.x.push_back(standardised(r, pts[i], i, r.predicted_before[i]));
        h_before.y.push_back(it->second);
        if (r.explanation) {
            h_after.x.push_back(standardised(r, pts[i], i, r.predicted_after[i]));
            h_after.y.push_back(it->second);
        }
    }
    if (!h_before.x.empty()) {
        for (auto* s : {&h_before, &h_after}) {
            s->marker_radius_px = 2.6;
            s->opacity = 0.6;
        }
        pl::Figure fig;
        fig.width_px = 560;
        fig.height_px = 620;
        fig.title = "Residual against the zone's height";
        fig.notes.push_back("dashed: the air probe's height (1.1 m) and no residual");
        pl::XYPanel hp;
        hp.box = {0, 46, 560, 554};
        hp.x.label = "(Q_exp − Q_sim)/σ";
        hp.y.label = "Zone centroid height (m)";
        hp.reference_lines.push_back({false, 0.0, "#888888", "4 3"});
        hp.reference_lines.push_back({true, 1.1, "#888888", "4 3"});
        hp.series.push_back(h_before);
        if (r.explanation) hp.series.push_back(h_after);
        fig.xy_panels.push_back(std::move(hp));
        const auto h_path = dir / plot_file_names()[3];
        pl::write_svg(fig, h_path);
        written.push_back(h_path);
    }
    return written;
}

}  // namespace manikind::analysis::reconcile
