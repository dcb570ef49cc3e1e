#pragma once
// When will the enclosure be on target? A chamber closes on its setpoint as a first-order system,
// |off|(t) = A exp(-t / tau): a line through the last minutes' distances (the old estimate) runs
// out of distance too early, and said "ready in about 23 min" where the enclosure took 45
// (issue 64). The fit is ln|off| linear in t, least squares; its slope's standard error gives
// the ETA's own range.
#include <optional>
#include <utility>
#include <vector>

namespace manikind::analysis {

struct SettlingEta {
    double eta_s = 0.0;     // from the last point to |off| = tolerance
    double low_s = 0.0;     // the same from tau - 2 se (sooner) and tau + 2 se (later, may be
    double high_s = 0.0;    // unbounded: +inf when the slope is not surely negative)
    double tau_s = 0.0;     // the fitted time constant
    double tau_short_s = 0.0, tau_long_s = 0.0;  // at slope -/+ 2 se (tau_long_s +inf when not surely closing)
};

// `t_off`: (time in s, distance from target, same unit as `tolerance`), oldest first. None when
// fewer than 3 points or it is not closing in; within the tolerance already, the ETAs are 0.
std::optional<SettlingEta> first_order_eta(const std::vector<std::pair<double, double>>& t_off, double tolerance);

// When a settling criterion of the daemon's kind holds: within `tolerance` for `window_s` and
// varying less than `band` over that window. On the fitted approach the range over a trailing
// window W is |off|(t) (e^(W/tau) - 1), so the band holds once |off| < band / (e^(W/tau) - 1);
// ready = max(reaching the tolerance + the window, reaching that), from now (`on_target_s` of the
// window already done). Applied to each of `fit`'s taus: the ETA and its range.
SettlingEta settling_ready(const SettlingEta& fit, double off_now, double tolerance, double band, double window_s,
                           double on_target_s);

}  // namespace manikind::analysis
