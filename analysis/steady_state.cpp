#include "analysis/steady_state.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/core.h>

namespace manikind::analysis {

namespace {

struct WindowStats {
    std::size_t count = 0;
    double min = std::numeric_limits<double>::infinity();
    double max = -std::numeric_limits<double>::infinity();
    double longest_gap_s = 0.0;  // including the window's edges
};

// Finite samples of `values` with t in [start, end], their range and the longest gap.
WindowStats window_stats(const std::vector<double>& t_s, const std::vector<double>& values, std::size_t first,
                         double start_s, double end_s) {
    WindowStats s;
    double last_t = start_s;
    for (std::size_t i = first; i < t_s.size(); ++i) {
        const double v = values[i];
        if (!std::isfinite(v)) continue;
        ++s.count;
        s.min = std::min(s.min, v);
        s.max = std::max(s.max, v);
        s.longest_gap_s = std::max(s.longest_gap_s, t_s[i] - last_t);
        last_t = t_s[i];
    }
    s.longest_gap_s = std::max(s.longest_gap_s, end_s - last_t);
    return s;
}

// Least-squares line through the finite samples from index `first` on.
struct LineFit {
    double n = 0.0;
    double slope_per_s = kNaN;
    double residual_sd = 0.0;
    double u_slope_per_s = kNaN;        // white-noise standard uncertainty, s_res / sqrt(Stt)
    double lag1_autocorrelation = 0.0;  // of the residuals, consecutive finite samples
};

LineFit fit_line(const std::vector<double>& t_s, const std::vector<double>& v, std::size_t first) {
    LineFit f;
    // Plain sums, divided once: a running mean's division per sample is a chain of dependent
    // divisions, and it was 7 % of `manikin analyze`. A trial's sums are far from overflow.
    double sum_t = 0.0, sum_v = 0.0;
    for (std::size_t i = first; i < t_s.size(); ++i) {
        if (!std::isfinite(v[i])) continue;
        f.n += 1.0;
        sum_t += t_s[i];
        sum_v += v[i];
    }
    if (f.n < 3.0) return f;
    const double mean_t = sum_t / f.n, mean_v = sum_v / f.n;
    double stt = 0.0, stv = 0.0;
    for (std::size_t i = first; i < t_s.size(); ++i) {
        if (!std::isfinite(v[i])) continue;
        stt += (t_s[i] - mean_t) * (t_s[i] - mean_t);
        stv += (t_s[i] - mean_t) * (v[i] - mean_v);
    }
    f.slope_per_s = stt > 0.0 ? stv / stt : 0.0;
    double ss = 0.0, lag1 = 0.0, previous = kNaN;
    for (std::size_t i = first; i < t_s.size(); ++i) {
        if (!std::isfinite(v[i])) continue;
        const double r = v[i] - (mean_v + f.slope_per_s * (t_s[i] - mean_t));
        ss += r * r;
        if (!std::isnan(previous)) lag1 += r * previous;
        previous = r;
    }
    f.residual_sd = std::sqrt(ss / (f.n - 2.0));
    f.u_slope_per_s = stt > 0.0 ? f.residual_sd / std::sqrt(stt) : kNaN;
    f.lag1_autocorrelation = ss > 0.0 ? lag1 / ss : 0.0;
    return f;
}

// Drift = |slope| x window, and the residual standard deviation about the line.
void flux_line(const std::vector<double>& t_s, const std::vector<double>& q, std::size_t first, double window_s,
               double& drift_w_m2, double& sd_w_m2) {
    const LineFit f = fit_line(t_s, q, first);
    drift_w_m2 = f.n < 3.0 ? 0.0 : std::fabs(f.slope_per_s) * window_s;
    sd_w_m2 = f.n < 3.0 ? 0.0 : f.residual_sd;
}

// A zone's skin temperature over the window: range (Text S3) and least-squares drift.
ZoneSkinDrift skin_drift(int zone, const std::vector<double>& t_s, const std::vector<double>& skin_c,
                         std::size_t first, const WindowStats& stats) {
    ZoneSkinDrift d;
    d.zone = zone;
    d.samples = stats.count;
    d.range_c = stats.count ? stats.max - stats.min : kNaN;
    const LineFit f = fit_line(t_s, skin_c, first);
    d.drift_c_per_30min = f.slope_per_s * kDriftInterval_s;
    d.residual_sd_c = f.residual_sd;
    d.lag1_autocorrelation = f.lag1_autocorrelation;
    // AR(1) residuals: var(slope) grows by about (1 + r1)/(1 - r1) (effective sample size).
    const double r1 = std::clamp(f.lag1_autocorrelation, 0.0, 0.999);
    d.u_drift_c_per_30min = f.u_slope_per_s * kDriftInterval_s * std::sqrt((1.0 + r1) / (1.0 - r1));
    return d;
}

// Earliest time from which this zone stays within `tolerance` to the end (scanning back),
// stopping at a gap longer than max_gap_s. NaN when the zone has no finite sample.
double settled_since(const std::vector<double>& t_s, const std::vector<double>& values, double tolerance,
                     double max_gap_s) {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    double since = kNaN;
    for (std::size_t k = t_s.size(); k-- > 0;) {
        const double v = values[k];
        if (!std::isfinite(v)) continue;
        if (!std::isnan(since) && since - t_s[k] > max_gap_s) break;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
        if (hi - lo > tolerance) break;
        since = t_s[k];
    }
    return since;
}

}  // namespace

SteadyStateResult detect_steady_state(const TrialData& data, const ZoneMap& map, const SteadyStateOptions& o) {
    SteadyStateResult r;
    if (data.rows() == 0) {
        r.reason = "empty trial: no samples";
        r.settled_since_s = kNaN;
        return r;
    }
    const double t_first = data.t_s.front();
    const double t_last = data.t_s.back();
    r.window_end_s = t_last;
    r.window_start_s = t_last - o.window_s;
    // Settled-since: the latest of the zones' settling times.
    r.settled_since_s = t_first;
    for (std::size_t z = 0; z < map.size(); ++z) {
        const double since = settled_since(data.t_s, data.skin_temp_c[z], o.max_skin_fluctuation_c, o.max_gap_s);
        if (std::isnan(since) || std::isnan(r.settled_since_s)) r.settled_since_s = kNaN;
        else r.settled_since_s = std::max(r.settled_since_s, since);
    }

    if (t_last - t_first < o.window_s) {
        r.reason = fmt::format("partial trial: the recording covers {:.1f} min, the steady window needs {:.1f} min",
                               (t_last - t_first) / 60.0, o.window_s / 60.0);
        r.window_start_s = t_first;
    }
    // Tiny tolerance so that a sample exactly at end - window counts despite rounding.
    const double start_s = r.window_start_s - 1e-9 * std::max(1.0, std::fabs(r.window_start_s));
    const auto first = static_cast<std::size_t>(
        std::lower_bound(data.t_s.begin(), data.t_s.end(), start_s) - data.t_s.begin());

    std::string coverage_problem;
    for (std::size_t z = 0; z < map.size(); ++z) {
        const int zone = map.zones[z].zone;
        const WindowStats skin = window_stats(data.t_s, data.skin_temp_c[z], first, r.window_start_s, t_last);
        const WindowStats flux = window_stats(data.t_s, data.heat_flux_w_m2[z], first, r.window_start_s, t_last);
        r.zone_skin.push_back(skin_drift(zone, data.t_s, data.skin_temp_c[z], first, skin));
        const auto& sd_zone = r.zone_skin.back();
        if (std::isfinite(sd_zone.drift_c_per_30min) &&
            (r.worst_skin_drift_zone == 0 || std::fabs(sd_zone.drift_c_per_30min) > std::fabs(r.max_skin_drift_c_per_30min))) {
            r.max_skin_drift_c_per_30min = sd_zone.drift_c_per_30min;
            r.u_max_skin_drift_c_per_30min = sd_zone.u_drift_c_per_30min;
            r.worst_skin_drift_zone = zone;
        }
        if (skin.count == 0 || flux.count == 0) {
            if (coverage_problem.empty())
                coverage_problem = fmt::format("zone {:02} ({}) has no {} sample in the window", zone, map.zones[z].name,
                                               skin.count == 0 ? "skin-temperature" : "heat-flux");
            continue;
        }
        const double fluctuation_c = skin.max - skin.min;
        if (r.worst_zone == 0 || fluctuation_c > r.max_skin_fluctuation_c) {
            r.max_skin_fluctuation_c = fluctuation_c;
            r.worst_zone = zone;
        }
        const double gap_s = std::max(skin.longest_gap_s, flux.longest_gap_s);
        if (gap_s > o.max_gap_s && coverage_problem.empty())
            coverage_problem = fmt::format("zone {:02} ({}) has a {:.0f} s gap in the window (limit {:.0f} s: missing rows "
                                           "or empty cells)", zone, map.zones[z].name, gap_s, o.max_gap_s);
        double drift = 0.0, sd = 0.0;
        flux_line(data.t_s, data.heat_flux_w_m2[z], first, o.window_s, drift, sd);
        r.zone_flux_drift_w_m2.resize(map.size(), 0.0);
        r.zone_flux_drift_w_m2[z] = drift;
        if (drift > r.max_flux_drift_w_m2) {
            r.max_flux_drift_w_m2 = drift;
            r.worst_flux_drift_zone = zone;
        }
        if (sd > r.max_flux_sd_w_m2) {
            r.max_flux_sd_w_m2 = sd;
            r.worst_flux_sd_zone = zone;
        }
    }

    {
        // The whole body: area-weighted heat loss and mean skin per row of the window (rows
        // with a zone missing are left out).
        HeatLossRule rule = o.heat_loss;
        rule.window_s = o.window_s;
        std::vector<double> t, q, skin;
        const double area = map.total_area_m2();
        for (std::size_t i = first; i < data.t_s.size(); ++i) {
            double qa = 0.0, sa = 0.0;
            bool complete = area > 0.0;
            for (std::size_t z = 0; z < map.size() && complete; ++z) {
                complete = std::isfinite(data.heat_flux_w_m2[z][i]) && std::isfinite(data.skin_temp_c[z][i]);
                qa += map.zones[z].area_m2 * data.heat_flux_w_m2[z][i];
                sa += map.zones[z].area_m2 * data.skin_temp_c[z][i];
            }
            if (!complete) continue;
            t.push_back(data.t_s[i]);
            q.push_back(qa / area);
            skin.push_back(sa / area);
        }
        r.heat_loss = judge_heat_loss(t, q, skin, rule);
    }

    if (!r.reason.empty()) return r;  // partial trial
    if (!coverage_problem.empty()) {
        r.reason = "incomplete window: " + coverage_problem;
        return r;
    }
    if (r.max_skin_fluctuation_c > o.max_skin_fluctuation_c) {
        const auto& worst = map.zones[static_cast<std::size_t>(r.worst_zone - 1)];
        r.reason = fmt::format("never settled: zone {:02} ({}) skin temperature varies by {:.3f} °C over the final {:.0f} min "
                               "(limit {:.3f} °C)", r.worst_zone, worst.name, r.max_skin_fluctuation_c, o.window_s / 60.0,
                               o.max_skin_fluctuation_c);
        if (std::isfinite(r.settled_since_s) && r.settled_since_s > t_first)
            r.reason += fmt::format("; within the limit only since t = {:.0f} s ({:.1f} min before the end)",
                                    r.settled_since_s, (t_last - r.settled_since_s) / 60.0);
        return r;
    }
    if (o.require_heat_loss_stability && !r.heat_loss.steady) {
        r.reason = "heat loss still moving (the clothing standards' rule): " + r.heat_loss.failing;
        return r;
    }
    if (o.require_flux_stability) {
        if (r.max_flux_drift_w_m2 > o.max_flux_drift_w_m2) {
            r.reason = fmt::format("heat flux drifts: zone {:02} by {:.2f} W/m² over the window (limit {:.2f} W/m²)",
                                   r.worst_flux_drift_zone, r.max_flux_drift_w_m2, o.max_flux_drift_w_m2);
            return r;
        }
        if (r.max_flux_sd_w_m2 > o.max_flux_sd_w_m2) {
            r.reason = fmt::format("heat flux scatters: zone {:02} has SD {:.2f} W/m² about its trend (limit {:.2f} W/m²)",
                                   r.worst_flux_sd_zone, r.max_flux_sd_w_m2, o.max_flux_sd_w_m2);
            return r;
        }
    }
    r.steady = true;
    return r;
}

}  // namespace manikind::analysis
