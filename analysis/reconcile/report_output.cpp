#include "analysis/reconcile/report_output.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include <fmt/core.h>

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

// A minimal SVG canvas: data coordinates mapped into a plot frame with ticks.
class Svg {
public:
    Svg(double x0, double x1, double y0, double y1, const std::string& title, const std::string& xlabel,
        const std::string& ylabel)
        : x0_(x0), x1_(x1), y0_(y0), y1_(y1) {
        out_ << R"(<svg xmlns="http://www.w3.org/2000/svg" width="640" height="520" font-family="Helvetica,Arial,sans-serif" font-size="12">)"
             << "\n<rect width=\"640\" height=\"520\" fill=\"white\"/>\n"
             << fmt::format("<text x=\"320\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">{}</text>\n", title)
             << fmt::format("<text x=\"{}\" y=\"505\" text-anchor=\"middle\">{}</text>\n", left_ + width_ / 2, xlabel)
             << fmt::format("<text x=\"18\" y=\"{}\" text-anchor=\"middle\" transform=\"rotate(-90 18 {})\">{}</text>\n",
                            top_ + height_ / 2, top_ + height_ / 2, ylabel)
             << fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"black\"/>\n", left_,
                            top_, width_, height_);
        for (int i = 0; i <= 5; ++i) {
            const double xv = x0_ + (x1_ - x0_) * i / 5.0, yv = y0_ + (y1_ - y0_) * i / 5.0;
            out_ << fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{:.3g}</text>\n", px(xv), top_ + height_ + 16, xv)
                 << fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">{:.3g}</text>\n", left_ - 6, py(yv) + 4, yv);
        }
    }
    double px(double x) const { return left_ + (x - x0_) / (x1_ - x0_) * width_; }
    double py(double y) const { return top_ + height_ - (y - y0_) / (y1_ - y0_) * height_; }
    void line(double xa, double ya, double xb, double yb, const std::string& style) {
        out_ << fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" {}/>\n", px(xa), py(ya), px(xb), py(yb), style);
    }
    void point(double x, double y, const std::string& color) {
        out_ << fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"2.6\" fill=\"{}\" fill-opacity=\"0.75\"/>\n", px(x), py(y), color);
    }
    void legend(int row, const std::string& color, const std::string& text) {
        out_ << fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"4\" fill=\"{}\"/><text x=\"{}\" y=\"{}\">{}</text>\n", left_ + 14,
                            top_ + 16 + 16 * row, color, left_ + 24, top_ + 20 + 16 * row, text);
    }
    std::string finish() { return out_.str() + "</svg>\n"; }

private:
    double x0_, x1_, y0_, y1_;
    int left_ = 70, top_ = 40, width_ = 540, height_ = 420;
    std::ostringstream out_;
};

void write_file(const std::filesystem::path& p, const std::string& text) {
    std::ofstream f(p, std::ios::binary);
    f << text;
    if (!f) throw std::runtime_error("cannot write " + p.string());
}

}  // namespace

nlohmann::json report_to_json(const Report& r, const ForwardModel& model) {
    nlohmann::json j;
    j["twin"] = r.twin_name;
    j["before"] = stats_json(r.before);
    j["consistent_before"] = r.consistent_before;
    j["gof_p_before"] = r.gof_p_before;
    const auto& n = r.noise;
    nlohmann::json zone_sd = nlohmann::json::object();
    for (const auto& [zone, sd] : n.zone_sd_w_m2) zone_sd[std::to_string(zone)] = sd;
    j["noise_model"] = {{"from_replicates", n.from_replicates}, {"random_dof", n.random_dof},
                        {"relative_sd", n.relative_sd}, {"trial_factor_sd", n.trial_factor_sd},
                        {"calibration_offset_u_w_m2", n.calibration_offset_u_w_m2},
                        {"calibration_gain_u", n.calibration_gain_u}, {"air_temp_u_c", n.air_temp_u_c},
                        {"wall_temp_u_c", n.wall_temp_u_c}, {"probe_shared_fraction", n.probe_shared_fraction}, {"rh_u", n.rh_u_text}, {"notes", n.notes}};
    j["claim_rule"] = {{"alpha", r.alpha}, {"null_simulations", r.null_simulations},
                       {"null_threshold_chi2", r.null_threshold}};
    j["anomalies"] = nlohmann::json::array();
    for (const auto& a : r.anomalies)
        j["anomalies"].push_back({{"zone", a.zone}, {"zone_name", a.zone_name}, {"offset_w_m2", a.offset_w_m2},
                                  {"u_w_m2", a.u_w_m2}, {"z", a.z}, {"cases_outside_ci", a.cases_outside}, {"cases", a.cases}});
    j["ambiguous_with"] = r.ambiguous_with;
    j["located"] = nlohmann::json::array();
    for (const auto& l : r.located) j["located"].push_back({{"where", l.where}, {"driver", l.driver}, {"strength", l.strength}});
    if (r.explanation) {
        auto e = candidate_json(*r.explanation);
        e["statement"] = r.statement;
        j["explanation"] = e;
    } else {
        j["explanation"] = nullptr;
    }
    j["statement"] = r.statement;
    j["candidates"] = nlohmann::json::array();
    for (const auto& c : r.candidates) j["candidates"].push_back(candidate_json(c));
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
    j["limits"] = nlohmann::json::array();
    for (const auto& d : plan.limits)
        j["limits"].push_back({{"term", d.label}, {"parameter", d.parameter}, {"unit", d.unit}, {"null", d.null_value},
                               {"replicates", d.replicates}, {"smallest_effect", d.value ? nlohmann::json(*d.value) : nlohmann::json()},
                               {"simulated_power", d.simulated_power}});
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
    o << "  * this campaign's replicates. Units: gamma K m3/kg, h0 W/m2K, delta_c and bias_c degC, r_m2k_w m2K/W;\n"
         "    fraction: the wet fraction below which a region's dryness is found. Each value is checked by simulating\n"
         "    400 campaigns with that effect: reconcile's evidence must pass the null and name the right term.\n";
    return o.str();
}

std::string report_to_text(const Report& r) {
    std::ostringstream o;
    auto stats_line = [](const FitStats& s) {
        return fmt::format("RMSE {:7.2f}   chi2/dof {:8.2f}   outside 95 % CI {:4d} of {}", s.rmse, s.chi2_per_dof, s.outside_ci, s.n_points);
    };
    o << "Twin: " << r.twin_name << "\n";
    o << "Before: " << stats_line(r.before) << "\n";
    const auto& n = r.noise;
    std::string factors;
    for (const auto& [name, sd] : n.trial_factor_sd) factors += fmt::format("{}{} {:.3g}", factors.empty() ? "" : ", ", name, sd);
    o << fmt::format("Noise:  {}; calibration ±{:.2f} W/m² + {:.1f} % shared by all points; probes' Type B "
                     "±{:.2f} °C air, RH {}, ±{:.2f} °C wall ({:.0f} % of that variance common to all cases, the rest "
                     "per case)\n",
                     n.from_replicates ? fmt::format("replicate scatter pooled per zone ({} dof), {:.1f} % of flux; "
                                                     "per trial shared: {}", n.random_dof, 100.0 * n.relative_sd, factors)
                                       : std::string("no replicates to pool"),
                     n.calibration_offset_u_w_m2, 100.0 * n.calibration_gain_u, n.air_temp_u_c, n.rh_u_text.empty() ? "-" : n.rh_u_text,
                     n.wall_temp_u_c, 100.0 * n.probe_shared_fraction);
    for (const auto& note : n.notes) o << "        " << note << "\n";
    o << fmt::format("Claim:  evidence (chi2 drop) beyond {:.1f}, what noise alone exceeds in {:.0f} % of {} simulated campaigns\n\n",
                     r.null_threshold, 100.0 * r.alpha, r.null_simulations);
    o << "Located:\n";
    for (const auto& l : r.located) o << fmt::format("  {}  (driver: {}, |r| = {:.2f})\n", l.where, l.driver, l.strength);
    o << "\nCandidates (best first):\n";
    o << fmt::format("  {:<44} {:>9} {:>9} {:>9}  {}\n", "term (± standard uncertainty)", "evidence", "LOO RMSE", "chi2/dof", "verdict");
    for (std::size_t i = 0; i < r.candidates.size() && i < 12; ++i) {
        const auto& c = r.candidates[i];
        std::string params;
        for (std::size_t k = 0; k < c.values.size(); ++k)
            params += fmt::format(" {}={:.4g}±{:.2g}", c.parameter_names[k], c.values[k], c.uncertainties[k]);
        o << fmt::format("  {:<44} {:>9.1f} {:>9} {:>9.2f}  {}\n", c.label + params, c.evidence,
                         c.loo_rmse ? fmt::format("{:.2f}", *c.loo_rmse) : "-", c.after.chi2_per_dof, c.reason);
    }
    if (r.candidates.size() > 12) o << fmt::format("  ... and {} more (--json lists all)\n", r.candidates.size() - 12);
    o << "\n" << (r.explanation ? "Explanation: " + r.explanation->label : std::string("Explanation: none")) << "\n  " << r.statement << "\n";
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

std::vector<std::filesystem::path> write_plots(const Report& r, const ForwardModel& model, const std::filesystem::path& dir,
                                               const std::string& unit) {
    std::filesystem::create_directories(dir);
    const auto& pts = model.points();
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        lo = std::min({lo, pts[i].q_exp - pts[i].expanded_u, r.predicted_before[i], r.predicted_after[i]});
        hi = std::max({hi, pts[i].q_exp + pts[i].expanded_u, r.predicted_before[i], r.predicted_after[i]});
    }
    const double pad = 0.05 * (hi - lo + 1e-9);
    lo -= pad;
    hi += pad;
    // Parity (like the paper's Fig. 1D): x = Q_exp with its 95 % CI, y = Q_sim.
    Svg parity(lo, hi, lo, hi, "Twin vs recordings (95 % CI bars)", "Q_exp (" + unit + ")", "Q_sim (" + unit + ")");
    parity.line(lo, lo, hi, hi, "stroke=\"#888\" stroke-dasharray=\"4 3\"");
    for (std::size_t i = 0; i < pts.size(); ++i) {
        parity.line(pts[i].q_exp - pts[i].expanded_u, r.predicted_before[i], pts[i].q_exp + pts[i].expanded_u,
                    r.predicted_before[i], "stroke=\"#d62728\" stroke-opacity=\"0.35\"");
        parity.point(pts[i].q_exp, r.predicted_before[i], "#d62728");
        if (r.explanation) {
            parity.line(pts[i].q_exp - pts[i].expanded_u, r.predicted_after[i], pts[i].q_exp + pts[i].expanded_u,
                        r.predicted_after[i], "stroke=\"#1f77b4\" stroke-opacity=\"0.35\"");
            parity.point(pts[i].q_exp, r.predicted_after[i], "#1f77b4");
        }
    }
    parity.legend(0, "#d62728", fmt::format("before: {} (RMSE {:.2f})", r.twin_name, r.before.rmse));
    if (r.explanation) parity.legend(1, "#1f77b4", fmt::format("after: + {} (RMSE {:.2f})", r.explanation->label, r.after.rmse));
    const auto parity_path = dir / "parity.svg";
    write_file(parity_path, parity.finish());

    // Residual vs the strongest driver.
    std::vector<double> x, y_before, y_after;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const auto it = pts[i].drivers.find(r.best_driver);
        if (it == pts[i].drivers.end()) continue;
        x.push_back(it->second);
        y_before.push_back(pts[i].q_exp - r.predicted_before[i]);
        y_after.push_back(pts[i].q_exp - r.predicted_after[i]);
    }
    std::vector<std::filesystem::path> written{parity_path};
    if (!x.empty()) {
        const auto [xmin, xmax] = std::minmax_element(x.begin(), x.end());
        double ylo = 0.0, yhi = 0.0;
        for (double v : y_before) ylo = std::min(ylo, v), yhi = std::max(yhi, v);
        for (double v : y_after) ylo = std::min(ylo, v), yhi = std::max(yhi, v);
        const double xpad = 0.05 * (*xmax - *xmin + 1e-9), ypad = 0.05 * (yhi - ylo + 1e-9);
        Svg res(*xmin - xpad, *xmax + xpad, ylo - ypad, yhi + ypad, "Residual vs " + r.best_driver, r.best_driver,
                "Q_exp - Q_sim (" + unit + ")");
        res.line(*xmin - xpad, 0.0, *xmax + xpad, 0.0, "stroke=\"#888\"");
        for (std::size_t i = 0; i < x.size(); ++i) {
            res.point(x[i], y_before[i], "#d62728");
            if (r.explanation) res.point(x[i], y_after[i], "#1f77b4");
        }
        res.legend(0, "#d62728", "before");
        if (r.explanation) res.legend(1, "#1f77b4", "after");
        const auto res_path = dir / "residual_vs_driver.svg";
        write_file(res_path, res.finish());
        written.push_back(res_path);
    }
    return written;
}

}  // namespace manikind::analysis::reconcile
