#include "analysis/heat_loss_steady.hpp"

#include <cmath>

#include <fmt/core.h>

namespace manikind::analysis {

namespace {
// Least-squares slope per second of the finite (t, v) pairs; NaN with fewer than 3.
double slope_per_s(const std::vector<double>& t, const std::vector<double>& v, double& mean_v) {
    double n = 0.0, st = 0.0, sv = 0.0;
    for (std::size_t i = 0; i < t.size(); ++i)
        if (std::isfinite(v[i])) n += 1.0, st += t[i], sv += v[i];
    mean_v = n > 0.0 ? sv / n : std::nan("");
    if (n < 3.0) return std::nan("");
    const double mt = st / n;
    double stt = 0.0, stv = 0.0;
    for (std::size_t i = 0; i < t.size(); ++i)
        if (std::isfinite(v[i])) stt += (t[i] - mt) * (t[i] - mt), stv += (t[i] - mt) * (v[i] - mean_v);
    return stt > 0.0 ? stv / stt : 0.0;
}
}  // namespace

HeatLossVerdict judge_heat_loss(const std::vector<double>& t_s, const std::vector<double>& heat_loss_w_m2,
                                const std::vector<double>& mean_skin_c, const HeatLossRule& rule) {
    HeatLossVerdict v;
    double mean_skin = 0.0;
    const double q_slope = slope_per_s(t_s, heat_loss_w_m2, v.mean_w_m2);
    const double skin_slope = slope_per_s(t_s, mean_skin_c, mean_skin);
    v.observed = t_s.size() >= 3 && t_s.back() - t_s.front() >= rule.window_s * 0.95 && std::isfinite(q_slope) &&
                 std::isfinite(skin_slope);
    if (!v.observed) {
        v.failing = "the heat loss has not been sampled over a whole window yet";
        return v;
    }
    v.drift_fraction = std::abs(v.mean_w_m2) > 0.0 ? std::abs(q_slope) * rule.window_s / std::abs(v.mean_w_m2) : 0.0;
    v.mean_skin_drift_c = std::abs(skin_slope) * rule.window_s;
    if (v.drift_fraction > rule.max_drift_fraction)
        v.failing = fmt::format("the whole-body heat loss moves {:.1f} % over {:.0f} min (limit {:.1f} %; {:.1f} W/m² mean)",
                                100.0 * v.drift_fraction, rule.window_s / 60.0, 100.0 * rule.max_drift_fraction, v.mean_w_m2);
    else if (v.mean_skin_drift_c > rule.max_mean_skin_drift_c)
        v.failing = fmt::format("the mean skin temperature moves {:.3f} °C over {:.0f} min (limit {:.2f} °C)",
                                v.mean_skin_drift_c, rule.window_s / 60.0, rule.max_mean_skin_drift_c);
    v.steady = v.failing.empty();
    return v;
}

void HeatLossWindow::push(std::int64_t t_ns, double heat_loss_w_m2, double mean_skin_c) {
    if (!std::isfinite(heat_loss_w_m2) || !std::isfinite(mean_skin_c)) return;
    samples_.push_back({t_ns, heat_loss_w_m2, mean_skin_c});
}

HeatLossVerdict HeatLossWindow::judge(const HeatLossRule& rule, std::int64_t now_ns, std::int64_t since_ns) {
    const auto window_ns = static_cast<std::int64_t>(rule.window_s * 1e9);
    while (!samples_.empty() && samples_.front().t_ns < now_ns - window_ns) samples_.pop_front();
    std::vector<double> t, q, skin;
    for (const auto& s : samples_) {
        t.push_back(static_cast<double>(s.t_ns - now_ns) * 1e-9);
        q.push_back(s.q);
        skin.push_back(s.skin);
    }
    HeatLossVerdict v = judge_heat_loss(t, q, skin, rule);
    if (now_ns - since_ns < window_ns) {
        v.observed = v.steady = false;
        v.failing = "the heat loss has not been sampled over a whole window yet";
    }
    return v;
}

}  // namespace manikind::analysis
