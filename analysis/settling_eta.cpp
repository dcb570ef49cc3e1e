#include "analysis/settling_eta.hpp"

#include <cmath>
#include <limits>

namespace manikind::analysis {

std::optional<SettlingEta> first_order_eta(const std::vector<std::pair<double, double>>& t_off, double tolerance) {
    if (t_off.size() < 3 || !(tolerance > 0.0)) return std::nullopt;
    const double now_off = std::abs(t_off.back().second);
    if (!std::isfinite(now_off)) return std::nullopt;
    // Least squares of y = ln|off| on t, over the points with a distance to take the log of.
    double n = 0.0, st = 0.0, sy = 0.0;
    for (const auto& [t, off] : t_off)
        if (std::isfinite(t) && std::isfinite(off) && std::abs(off) > 0.0) n += 1.0, st += t, sy += std::log(std::abs(off));
    if (n < 3.0) return std::nullopt;
    const double mt = st / n, my = sy / n;
    double stt = 0.0, sty = 0.0;
    for (const auto& [t, off] : t_off)
        if (std::isfinite(t) && std::isfinite(off) && std::abs(off) > 0.0) {
            const double y = std::log(std::abs(off));
            stt += (t - mt) * (t - mt);
            sty += (t - mt) * (y - my);
        }
    if (!(stt > 0.0)) return std::nullopt;
    const double slope = sty / stt;  // -1/tau
    if (!(slope < 0.0)) return std::nullopt;
    double sse = 0.0;
    for (const auto& [t, off] : t_off)
        if (std::isfinite(t) && std::isfinite(off) && std::abs(off) > 0.0) {
            const double r = std::log(std::abs(off)) - (my + slope * (t - mt));
            sse += r * r;
        }
    const double se = std::sqrt(sse / std::max(1.0, n - 2.0) / stt);
    // From the fitted distance now (not the last reading alone, which carries its noise).
    const double fitted_now = std::exp(my + slope * (t_off.back().first - mt));
    const double to_go = std::log(std::max(fitted_now, tolerance) / tolerance);  // ln(off / tol) >= 0
    SettlingEta e;
    e.tau_s = -1.0 / slope;
    e.tau_short_s = -1.0 / (slope - 2.0 * se);
    const double slow = slope + 2.0 * se;
    e.tau_long_s = slow < 0.0 ? -1.0 / slow : std::numeric_limits<double>::infinity();
    e.eta_s = to_go * e.tau_s;
    e.low_s = to_go * e.tau_short_s;
    e.high_s = std::isfinite(e.tau_long_s) ? to_go * e.tau_long_s : (to_go > 0.0 ? std::numeric_limits<double>::infinity() : 0.0);
    return e;
}

SettlingEta settling_ready(const SettlingEta& fit, double off_now, double tolerance, double band, double window_s,
                           double on_target_s) {
    const double off = std::abs(off_now);
    auto ready = [&](double tau_s) {
        if (!(tau_s > 0.0) || !std::isfinite(tau_s)) return std::numeric_limits<double>::infinity();
        const double to_tolerance = off > tolerance ? tau_s * std::log(off / tolerance) : 0.0;
        const double window_left = off > tolerance ? window_s : std::max(0.0, window_s - on_target_s);
        const double stable_below = band / std::expm1(window_s / tau_s);
        const double to_stable = off > stable_below && stable_below > 0.0 ? tau_s * std::log(off / stable_below) : 0.0;
        return std::max(to_tolerance + window_left, to_stable);
    };
    SettlingEta r = fit;
    r.eta_s = ready(fit.tau_s);
    r.low_s = ready(fit.tau_short_s);
    r.high_s = ready(fit.tau_long_s);
    return r;
}

}  // namespace manikind::analysis
