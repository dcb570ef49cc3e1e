// exp and log of quantities that move by tiny amounts from one time step to the next.
//
// The thermoregulation model evaluates, per segment and per step, the saturation pressure at the
// skin (an exp and a log) and the local vasomotor factor (an exp2). Skin temperatures move by
// millikelvin per 1-s step, so each new value is the old one times a factor close to 1 whose
// Taylor series converges after a few terms; an exact evaluation every `resync_every` steps
// (and after any large jump) keeps the rounding of the chained products from accumulating.
// Relative error stays below 1e-14 (tests/physics/test_stepwise_math.cpp), far under the 5e-9 °C
// to which the seed-compatible model reproduces the published code's output.
#pragma once

#include <cmath>
#include <limits>

namespace manikind::physics::thermoreg {

inline constexpr int resync_every = 64;
// Largest step taken by series: |d|^5 / 120 < 1e-17 for exp, |u|^5 / 5 < 1e-17 for log1p.
inline constexpr double series_step_limit = 1e-3;

// exp(x), tracked across calls.
class SteppedExp {
public:
    double operator()(double x) {
        const double d = x - x_;
        if (steps_since_exact_ < resync_every && std::abs(d) < series_step_limit) {
            value_ *= 1.0 + d * (1.0 + d * (0.5 + d * (1.0 / 6.0 + d * (1.0 / 24.0))));
            ++steps_since_exact_;
        } else {
            value_ = std::exp(x);
            steps_since_exact_ = 0;
        }
        x_ = x;
        return value_;
    }

private:
    double x_ = std::numeric_limits<double>::quiet_NaN();  // NaN: the first call is exact
    double value_ = 0.0;
    int steps_since_exact_ = resync_every;
};

// log(x) for x > 0, tracked across calls: log(x + h) = log(x) + log1p(h / x).
class SteppedLog {
public:
    double operator()(double x) {
        const double u = (x - x_) / x_;
        if (steps_since_exact_ < resync_every && std::abs(u) < series_step_limit) {
            value_ += u * (1.0 - u * (0.5 - u * (1.0 / 3.0 - u * 0.25)));
            ++steps_since_exact_;
        } else {
            value_ = std::log(x);
            steps_since_exact_ = 0;
        }
        x_ = x;
        return value_;
    }

private:
    double x_ = std::numeric_limits<double>::quiet_NaN();
    double value_ = 0.0;
    int steps_since_exact_ = resync_every;
};

}  // namespace manikind::physics::thermoreg
