#include "analysis/reconcile/reconcile.hpp"

#include <algorithm>
#include <cmath>
#include <future>
#include <limits>
#include <numeric>
#include <set>
#include <stdexcept>

#include <fmt/core.h>

#include "analysis/reconcile/least_squares.hpp"
#include "physics/psychrometrics.hpp"

namespace manikind::analysis::reconcile {
namespace tw = physics::twin;
namespace {

// ---- Forward models ----------------------------------------------------------------------

class TwinModel final : public ForwardModel {
public:
    TwinModel(std::vector<CaseInput> cases, tw::TwinVersion base) : cases_(std::move(cases)), base_(std::move(base)) {
        for (std::size_t c = 0; c < cases_.size(); ++c) {
            const CaseInput& in = cases_[c];
            const auto& cond = in.conditions;
            const double p_air = physics::vapour_pressure_pa(cond.air_temp_c, cond.air_rh_pct);
            const double c_air = physics::vapour_concentration_kg_m3(p_air, cond.air_temp_c);
            for (std::size_t z = 0; z < cond.zones.size(); ++z) {
                const double q = in.q_exp_w_m2.at(z);
                const double u = in.expanded_u_w_m2.at(z);
                if (!std::isfinite(q) || !std::isfinite(u) || u <= 0.0) continue;
                Point p;
                p.case_id = in.case_id;
                p.zone = cond.zones[z].zone;
                p.zone_name = z < in.zone_names.size() ? in.zone_names[z] : std::to_string(p.zone);
                p.region = cond.zones[z].region;
                p.q_exp = q;
                p.expanded_u = u;
                p.coverage_k = z < in.coverage_k.size() && in.coverage_k[z] > 0.0 ? in.coverage_k[z] : 2.0;
                const double ts = cond.zones[z].skin_temp_c;
                p.drivers["skin-air temperature difference"] = ts - cond.air_temp_c;
                p.drivers["vapour concentration difference"] =
                    cond.wettedness * (physics::saturation_concentration_kg_m3(ts) - c_air);
                p.drivers["relative humidity"] = cond.air_rh_pct;
                p.drivers["air speed"] = cond.air_speed_m_s.value_or(0.0);
                p.drivers["wall-air temperature difference"] = cond.wall_temp_c.value_or(cond.air_temp_c) - cond.air_temp_c;
                p.drivers["wettedness"] = cond.wettedness;
                if (z < in.heights_m.size()) p.drivers["zone height"] = in.heights_m[z];
                if (z < in.sides.size()) p.drivers["side (left -1, right +1)"] = in.sides[z] == "l" ? -1.0 : in.sides[z] == "r" ? 1.0 : 0.0;
                points_.push_back(std::move(p));
                index_.emplace_back(c, z);
            }
        }
    }
    const std::vector<Point>& points() const override { return points_; }
    bool supports(const std::string&) const override { return true; }
    std::string base_name() const override { return base_.name; }
    std::vector<tw::Term> base_terms() const override { return base_.terms; }

    std::vector<double> predict(const std::vector<tw::Term>& extra) const override {
        tw::TwinVersion v = base_;
        v.terms.insert(v.terms.end(), extra.begin(), extra.end());
        std::vector<std::vector<tw::ZoneFlux>> per_case(cases_.size());
        for (std::size_t c = 0; c < cases_.size(); ++c) per_case[c] = tw::predict(v, cases_[c].conditions);
        std::vector<double> out(points_.size());
        for (std::size_t i = 0; i < points_.size(); ++i) out[i] = per_case[index_[i].first][index_[i].second].q_total_w_m2;
        return out;
    }

private:
    std::vector<CaseInput> cases_;
    tw::TwinVersion base_;
    std::vector<Point> points_;
    std::vector<std::pair<std::size_t, std::size_t>> index_;
};

class WholeBodyHModel final : public ForwardModel {
public:
    WholeBodyHModel(std::vector<HObservation> obs, double a, double exponent) : a_(a), exponent_(exponent) {
        for (const auto& o : obs) {
            Point p;
            p.case_id = o.case_id;
            p.zone_name = "whole body";
            p.region = "whole_body";
            p.q_exp = o.h_w_m2k;
            p.expanded_u = o.expanded_u_w_m2k;
            p.coverage_k = o.coverage_k;
            const double c_air = physics::vapour_concentration_kg_m3(physics::vapour_pressure_pa(o.air_temp_c, o.air_rh_pct), o.air_temp_c);
            dt_.push_back(o.skin_temp_c - o.air_temp_c);
            dc_.push_back(physics::saturation_concentration_kg_m3(o.skin_temp_c) - c_air);
            p.drivers["skin-air temperature difference"] = dt_.back();
            p.drivers["vapour concentration difference"] = dc_.back();
            p.drivers["relative humidity"] = o.air_rh_pct;
            points_.push_back(std::move(p));
        }
    }
    const std::vector<Point>& points() const override { return points_; }
    bool supports(const std::string& term) const override {
        return term == "humidity_buoyancy" || term == "diffusion_floor";
    }
    std::string base_name() const override { return fmt::format("h = {} |dT|^{}", a_, exponent_); }
    std::vector<tw::Term> base_terms() const override { return {}; }
    std::vector<double> predict(const std::vector<tw::Term>& extra) const override {
        double gamma = 0.0, h0 = 0.0;
        for (const auto& t : extra) {
            if (t.name == "humidity_buoyancy") gamma = t.parameters.at("gamma");
            else if (t.name == "diffusion_floor") h0 = t.parameters.at("h0");
            else throw std::invalid_argument("whole-body h model does not support " + t.name);
        }
        std::vector<double> out(points_.size());
        for (std::size_t i = 0; i < points_.size(); ++i)
            out[i] = h0 + a_ * std::pow(std::abs(dt_[i] + gamma * dc_[i]), exponent_);
        return out;
    }

private:
    double a_, exponent_;
    std::vector<Point> points_;
    std::vector<double> dt_, dc_;
};

// ---- Statistics ----------------------------------------------------------------------------

FitStats stats_of(const std::vector<Point>& pts, const std::vector<double>& pred, int n_params,
                  const std::vector<std::size_t>* subset = nullptr) {
    FitStats s;
    double sum_sq = 0.0, chi2 = 0.0;
    auto add = [&](std::size_t i) {
        const double r = pts[i].q_exp - pred[i];
        sum_sq += r * r;
        chi2 += (r / pts[i].standard_u()) * (r / pts[i].standard_u());
        s.outside_ci += std::abs(r) > pts[i].expanded_u ? 1 : 0;
        ++s.n_points;
    };
    if (subset) for (auto i : *subset) add(i);
    else for (std::size_t i = 0; i < pts.size(); ++i) add(i);
    if (s.n_points == 0) return s;
    s.rmse = std::sqrt(sum_sq / s.n_points);
    s.chi2_per_dof = chi2 / std::max(1, s.n_points - n_params);
    return s;
}

std::vector<tw::Term> to_terms(const std::vector<CandidateTerm>& terms, const std::vector<double>& values) {
    std::vector<tw::Term> out;
    std::size_t k = 0;
    for (const auto& c : terms) {
        tw::Term t;
        t.name = c.term;
        t.region = c.region;
        for (const auto& p : c.parameters) t.parameters[p.name] = values.at(k++);
        out.push_back(std::move(t));
    }
    return out;
}

std::string compress_ids(std::vector<int> ids) {
    std::sort(ids.begin(), ids.end());
    std::string out;
    for (std::size_t i = 0; i < ids.size();) {
        std::size_t j = i;
        while (j + 1 < ids.size() && ids[j + 1] == ids[j] + 1) ++j;
        out += (out.empty() ? "" : ", ") + (j > i + 1 ? fmt::format("{}-{}", ids[i], ids[j])
                                            : j == i + 1 ? fmt::format("{}, {}", ids[i], ids[j])
                                                         : std::to_string(ids[i]));
        i = j + 1;
    }
    return out;
}

double pearson(const std::vector<double>& x, const std::vector<double>& y) {
    const double n = static_cast<double>(x.size());
    if (x.size() < 3) return 0.0;
    const double mx = std::accumulate(x.begin(), x.end(), 0.0) / n;
    const double my = std::accumulate(y.begin(), y.end(), 0.0) / n;
    double sxy = 0.0, sxx = 0.0, syy = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) {
        sxy += (x[i] - mx) * (y[i] - my);
        sxx += (x[i] - mx) * (x[i] - mx);
        syy += (y[i] - my) * (y[i] - my);
    }
    if (sxx <= 1e-300 || syy <= 1e-300) return 0.0;
    return sxy / std::sqrt(sxx * syy);
}

// Where the residual is: a few zones, some cases, some regions, or everywhere.
std::string locate_where(const std::vector<Point>& pts, const std::vector<double>& pred) {
    std::map<int, std::pair<int, int>> by_case, by_zone;  // outside, total
    std::map<std::string, std::pair<int, int>> by_region;
    std::map<int, std::string> zone_names;
    int outside_total = 0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const bool out = std::abs(pts[i].q_exp - pred[i]) > pts[i].expanded_u;
        outside_total += out ? 1 : 0;
        auto bump = [&](auto& m, const auto& key) {
            m[key].first += out ? 1 : 0;
            m[key].second += 1;
        };
        bump(by_case, pts[i].case_id);
        bump(by_zone, pts[i].zone);
        bump(by_region, pts[i].region);
        zone_names[pts[i].zone] = pts[i].zone_name;
    }
    if (outside_total == 0) return "nowhere: every point is inside its 95 % CI";
    // Localised: a handful of zones out in most cases carry most of the mismatch.
    std::vector<int> hot_zones;
    int hot_outside = 0;
    for (const auto& [zone, c] : by_zone)
        if (c.second > 0 && c.first >= 0.75 * c.second) {
            hot_zones.push_back(zone);
            hot_outside += c.first;
        }
    if (!hot_zones.empty() && hot_zones.size() <= 4 && hot_outside >= 0.6 * outside_total && by_zone.size() > 4) {
        std::string names;
        for (int z : hot_zones) names += fmt::format("{}{} ({})", names.empty() ? "" : ", ", z, zone_names[z]);
        return fmt::format("zones {} only, in {} of {} cases", names, hot_outside / static_cast<int>(hot_zones.size()),
                           by_case.size());
    }
    std::vector<int> cases;
    for (const auto& [id, c] : by_case)
        if (c.first >= 0.5 * c.second) cases.push_back(id);
    std::vector<std::string> regions;
    for (const auto& [r, c] : by_region)
        if (c.first >= 0.5 * c.second) regions.push_back(r);
    std::string region_text = regions.size() == by_region.size() ? "all regions"
                              : 4 * regions.size() >= 3 * by_region.size() ? "most regions" : "";
    if (region_text.empty()) {
        for (const auto& r : regions) region_text += (region_text.empty() ? "" : ", ") + r;
        if (region_text.empty()) region_text = "scattered regions";
    }
    const std::string case_text = cases.empty() ? "no single case" : cases.size() == by_case.size() ? "all cases" : "cases " + compress_ids(cases);
    return fmt::format("{}, {}", case_text, region_text);
}

struct Fitted {
    FitResult fit;
    std::vector<double> prediction;
};

Fitted fit_terms(const ForwardModel& model, const std::vector<CandidateTerm>& terms, const std::vector<bool>& use,
                 const std::vector<double>* start = nullptr) {
    const auto& pts = model.points();
    std::vector<double> x0;
    std::vector<Bounds> bounds;
    for (const auto& t : terms)
        for (const auto& p : t.parameters) {
            x0.push_back(p.start);
            bounds.push_back({p.lo, p.hi});
        }
    auto residuals = [&](const std::vector<double>& x) {
        std::vector<double> r;
        std::vector<double> pred;
        try {
            pred = model.predict(to_terms(terms, x));
        } catch (const std::exception&) {
            // A parameter set the physics cannot evaluate (e.g. a surface driven out of range)
            // is as bad as a fit can be; the search steps away from it.
            pred.assign(pts.size(), std::numeric_limits<double>::quiet_NaN());
        }
        r.reserve(pts.size());
        for (std::size_t i = 0; i < pts.size(); ++i)
            if (use[i]) r.push_back(std::isfinite(pred[i]) ? (pts[i].q_exp - pred[i]) / pts[i].standard_u() : 1e6);
        return r;
    };
    if (start) {
        x0 = *start;
    } else {
        // |dT|^(1/4) is not smooth where dT crosses zero, so a local search can stall on a
        // ridge: start from the best point of a scan across the bounds (25 points for one
        // parameter, 9 x 9 for two), keeping the library's own start if it is better.
        const int steps = x0.size() == 1 ? 24 : 8;
        auto chi2_at = [&](const std::vector<double>& x) {
            double chi2 = 0.0;
            for (double v : residuals(x)) chi2 += v * v;
            return chi2;
        };
        double best = chi2_at(x0);
        std::vector<int> idx(x0.size(), 0);
        for (bool more = x0.size() <= 2; more;) {
            std::vector<double> x(x0.size());
            for (std::size_t d = 0; d < x.size(); ++d) x[d] = bounds[d].lo + (bounds[d].hi - bounds[d].lo) * idx[d] / steps;
            const double chi2 = chi2_at(x);
            if (chi2 < best) {
                best = chi2;
                x0 = x;
            }
            std::size_t d = 0;
            while (d < idx.size() && ++idx[d] > steps) idx[d++] = 0;
            more = d < idx.size();
        }
    }
    Fitted f;
    f.fit = fit_weighted_least_squares(residuals, x0, bounds);
    f.prediction = model.predict(to_terms(terms, f.fit.parameters));
    return f;
}

CandidateResult evaluate(const ForwardModel& model, const std::vector<CandidateTerm>& terms, double base_bic,
                         const Options& opt, bool consistent_before) {
    const auto& pts = model.points();
    const std::vector<bool> all(pts.size(), true);
    const Fitted f = fit_terms(model, terms, all);
    CandidateResult r;
    r.terms = terms;
    for (const auto& t : terms) {
        r.label += (r.label.empty() ? "" : " + ") + t.label();
        for (const auto& p : t.parameters) r.parameter_names.push_back(p.name);
    }
    r.values = f.fit.parameters;
    r.uncertainties = f.fit.standard_errors;
    r.chi2 = f.fit.chi2;
    const double n = static_cast<double>(pts.size());
    r.bic = r.chi2 + static_cast<double>(r.values.size()) * std::log(n);
    r.delta_bic = r.bic - base_bic;
    r.after = stats_of(pts, f.prediction, static_cast<int>(r.values.size()));

    // Verdict, in the order a reviewer would ask.
    std::size_t k = 0;
    std::string problem;
    for (const auto& t : terms)
        for (const auto& p : t.parameters) {
            const double v = r.values[k], u = r.uncertainties[k];
            ++k;
            const double span = p.hi - p.lo;
            if (v <= p.lo + 1e-3 * span || v >= p.hi - 1e-3 * span) {
                problem = fmt::format("{} = {:.4g} sits at its bound [{}, {}]", p.name, v, p.lo, p.hi);
                break;
            }
            if (!std::isfinite(u) || std::abs(v - p.null_value) < 2.0 * u) {
                problem = fmt::format("{} = {:.4g} ± {:.2g} is not distinguishable from no effect ({})", p.name, v, u, p.null_value);
                break;
            }
            if (v < p.plausible_lo || v > p.plausible_hi) {
                problem = fmt::format("{} = {:.4g} is physically implausible (expected {}..{} {})", p.name, v,
                                      p.plausible_lo, p.plausible_hi, p.unit);
                break;
            }
        }
    if (consistent_before) r.reason = "not needed: the twin already agrees with the recordings within their CIs";
    else if (!problem.empty()) r.reason = problem;
    else if (r.delta_bic > opt.min_delta_bic)
        r.reason = fmt::format("too little improvement (delta BIC {:.1f}, need <= {:.0f})", r.delta_bic, opt.min_delta_bic);
    else if (r.after.chi2_per_dof > opt.max_chi2_per_dof_after)
        r.reason = fmt::format("improves the fit but leaves it outside the CIs (chi2/dof {:.2f} after)", r.after.chi2_per_dof);
    else {
        r.accepted = true;
        r.reason = "explains the residual";
    }
    return r;
}

// Leave one case out: refit without it (from the full fit), predict it; RMSE over all points.
void leave_one_case_out(const ForwardModel& model, CandidateResult& r) {
    const auto& pts = model.points();
    std::set<int> case_ids;
    for (const auto& p : pts) case_ids.insert(p.case_id);
    if (case_ids.size() < 2) return;
    double sum_sq = 0.0;
    int count = 0;
    for (int c : case_ids) {
        std::vector<bool> use(pts.size());
        for (std::size_t i = 0; i < pts.size(); ++i) use[i] = pts[i].case_id != c;
        const Fitted g = fit_terms(model, r.terms, use, &r.values);
        for (std::size_t i = 0; i < pts.size(); ++i)
            if (!use[i]) {
                const double e = pts[i].q_exp - g.prediction[i];
                sum_sq += e * e;
                ++count;
            }
    }
    if (count > 0) r.loo_rmse = std::sqrt(sum_sq / count);
}

}  // namespace

std::unique_ptr<ForwardModel> make_twin_model(std::vector<CaseInput> cases, tw::TwinVersion base) {
    return std::make_unique<TwinModel>(std::move(cases), std::move(base));
}

std::unique_ptr<ForwardModel> make_whole_body_h_model(std::vector<HObservation> obs, double a, double exponent) {
    return std::make_unique<WholeBodyHModel>(std::move(obs), a, exponent);
}

Report reconcile(const ForwardModel& model, const Options& opt) {
    const auto& pts = model.points();
    if (pts.empty()) throw std::invalid_argument("reconcile: no observations with a finite value and uncertainty");
    Report rep;
    rep.twin_name = model.base_name();
    rep.predicted_before = model.predict({});
    rep.before = stats_of(pts, rep.predicted_before, 0);
    const double n = static_cast<double>(pts.size());
    // Consistent: chi2/dof near 1 and no more points outside than a 95 % CI allows (+2 slack).
    rep.consistent_before = rep.before.chi2_per_dof <= 1.5 && rep.before.outside_ci <= 0.05 * n + 2;

    // Locate.
    std::vector<double> s(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) s[i] = (pts[i].q_exp - rep.predicted_before[i]) / pts[i].standard_u();
    std::vector<std::pair<double, std::string>> drivers;
    std::set<std::string> names;
    for (const auto& p : pts)
        for (const auto& [k, v] : p.drivers) names.insert(k);
    for (const auto& name : names) {
        std::vector<double> x, y;
        for (std::size_t i = 0; i < pts.size(); ++i) {
            const auto it = pts[i].drivers.find(name);
            if (it == pts[i].drivers.end()) continue;
            x.push_back(it->second);
            y.push_back(s[i]);
        }
        drivers.emplace_back(std::abs(pearson(x, y)), name);
    }
    std::sort(drivers.rbegin(), drivers.rend());
    const std::string where = locate_where(pts, rep.predicted_before);
    for (std::size_t i = 0; i < drivers.size() && i < 3; ++i)
        if (drivers[i].first > 0.0) rep.located.push_back({where, drivers[i].second, drivers[i].first});
    if (rep.located.empty()) rep.located.push_back({where, "none", 0.0});
    rep.best_driver = rep.located.front().driver;

    // Explain: every supported candidate, then pairs of the promising ones.
    std::set<std::string> wet_regions;
    for (const auto& p : pts) {
        const auto it = p.drivers.find("wettedness");
        if (it != p.drivers.end() && it->second > 0.0) wet_regions.insert(p.region);
    }
    std::vector<CandidateTerm> library;
    for (auto& c : candidate_library({wet_regions.begin(), wet_regions.end()}))
        if (model.supports(c.term)) library.push_back(std::move(c));
    const double base_bic = rep.before.chi2_per_dof * std::max(1, rep.before.n_points);  // chi2, no parameters

    // Two cores: evaluate candidates in two halves concurrently (each fit is independent).
    auto run = [&](const std::vector<std::vector<CandidateTerm>>& sets) {
        std::vector<CandidateResult> results(sets.size());
        auto worker = [&](std::size_t begin, std::size_t step) {
            for (std::size_t i = begin; i < sets.size(); i += step)
                results[i] = evaluate(model, sets[i], base_bic, opt, rep.consistent_before);
        };
        auto other = std::async(std::launch::async, worker, 1, 2);
        worker(0, 2);
        other.get();
        return results;
    };
    std::vector<std::vector<CandidateTerm>> singles;
    for (const auto& c : library) singles.push_back({c});
    std::vector<CandidateResult> results = run(singles);

    if (opt.try_pairs) {
        std::vector<std::size_t> promising;
        for (std::size_t i = 0; i < results.size(); ++i)
            if (results[i].delta_bic < -2.0) promising.push_back(i);
        std::sort(promising.begin(), promising.end(), [&](auto a, auto b) { return results[a].bic < results[b].bic; });
        if (promising.size() > 5) promising.resize(5);
            // Pairs among the promising singles, and the best single with every other term (a term
        // can only help in company, as the diffusion floor does beside humidity buoyancy).
        std::set<std::pair<std::size_t, std::size_t>> chosen;
        for (std::size_t a = 0; a < promising.size(); ++a)
            for (std::size_t b = a + 1; b < promising.size(); ++b)
                chosen.insert(std::minmax(promising[a], promising[b]));
        std::size_t best = 0;
        for (std::size_t i = 1; i < results.size(); ++i)
            if (results[i].bic < results[best].bic) best = i;
        if (!results.empty() && results[best].delta_bic < 0.0)
            for (std::size_t i = 0; i < singles.size(); ++i)
                if (i != best && singles[i][0].term != "partial_wettedness") chosen.insert(std::minmax(best, i));
        std::vector<std::vector<CandidateTerm>> pairs;
        for (const auto& [a, b] : chosen)
            if (singles[a][0].term != singles[b][0].term || singles[a][0].region != singles[b][0].region)
                pairs.push_back({singles[a][0], singles[b][0]});
        const auto pair_results = run(pairs);
        results.insert(results.end(), pair_results.begin(), pair_results.end());
    }
    std::sort(results.begin(), results.end(), [](const auto& a, const auto& b) { return a.bic < b.bic; });
    // Leave-one-case-out error for the leading candidates that improve on the twin (it costs a
    // refit per case, so the long tail of weak candidates is not cross-validated).
    {
        std::vector<std::size_t> top;
        for (std::size_t i = 0; i < results.size() && top.size() < 6; ++i)
            if (results[i].delta_bic < 0.0) top.push_back(i);
        auto worker = [&](std::size_t begin) {
            for (std::size_t i = begin; i < top.size(); i += 2) leave_one_case_out(model, results[top[i]]);
        };
        auto other = std::async(std::launch::async, worker, 1);
        worker(0);
        other.get();
    }

    // The winner: lowest BIC among accepted; a pair must beat its best accepted single by 6.
    const CandidateResult* winner = nullptr;
    for (const auto& r : results)
        if (r.accepted) {
            winner = &r;
            break;
        }
    if (winner && winner->terms.size() > 1) {
        for (const auto& r : results)
            if (r.accepted && r.terms.size() == 1 && r.bic - winner->bic < 6.0) {
                winner = &r;
                break;
            }
    }
    rep.candidates = results;

    rep.new_version.name = opt.new_version_name;
    rep.new_version.terms = model.base_terms();
    if (winner) {
        rep.explanation = *winner;
        const auto terms = to_terms(winner->terms, winner->values);
        rep.new_version.terms.insert(rep.new_version.terms.end(), terms.begin(), terms.end());
        rep.predicted_after = model.predict(terms);
        rep.after = stats_of(pts, rep.predicted_after, static_cast<int>(winner->values.size()));
        std::size_t k = 0;
        for (const auto& t : winner->terms) {
            const std::vector<double> v(winner->values.begin() + static_cast<long>(k), winner->values.begin() + static_cast<long>(k + t.parameters.size()));
            const std::vector<double> u(winner->uncertainties.begin() + static_cast<long>(k), winner->uncertainties.begin() + static_cast<long>(k + t.parameters.size()));
            rep.statement += (rep.statement.empty() ? "" : " ") + plain_statement(t, v, u);
            k += t.parameters.size();
        }
    } else {
        rep.new_version.name = model.base_name();
        rep.predicted_after = rep.predicted_before;
        rep.after = rep.before;
        rep.statement = rep.consistent_before
                            ? "The twin agrees with the recordings within their 95 % CIs; no physics is missing."
                            : fmt::format("No candidate term explains the mismatch. It is at {}; it correlates most "
                                          "with {} (|r| = {:.2f}). No explanation is claimed.",
                                          where, rep.located.front().driver, rep.located.front().strength);
    }

    std::set<int> case_ids;
    for (const auto& p : pts) case_ids.insert(p.case_id);
    for (int id : case_ids) {
        std::vector<std::size_t> idx;
        for (std::size_t i = 0; i < pts.size(); ++i)
            if (pts[i].case_id == id) idx.push_back(i);
        rep.by_case.push_back({id, {"", stats_of(pts, rep.predicted_before, 0, &idx), stats_of(pts, rep.predicted_after, 0, &idx)}});
    }
    std::set<std::string> regions;
    for (const auto& p : pts) regions.insert(p.region);
    for (const auto& region : regions) {
        std::vector<std::size_t> idx;
        for (std::size_t i = 0; i < pts.size(); ++i)
            if (pts[i].region == region) idx.push_back(i);
        rep.by_region.push_back({region, stats_of(pts, rep.predicted_before, 0, &idx),
                                 stats_of(pts, rep.predicted_after, 0, &idx)});
    }
    return rep;
}

}  // namespace manikind::analysis::reconcile
