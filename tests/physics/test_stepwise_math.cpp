#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "physics/thermoreg/stepwise_math.hpp"

using namespace manikind::physics::thermoreg;

namespace {
double relative_error(double got, double want) { return std::abs(got - want) / std::abs(want); }
}  // namespace

TEST_CASE("Stepped exp and log stay within 1e-14 of libm along a skin-temperature walk", "[thermoreg][stepwise]") {
    // A skin temperature in kelvin moving by up to 5 mK per step, as in a 1-s thermoregulation
    // run, with the arguments the model takes: ln T, the saturation pressure's exponent, and the
    // vasomotor exponent err * ln 2 / 30 (which crosses zero). Without the periodic exact
    // evaluation the chained rounding passes 1e-14 within this walk (checked by hand).
    std::mt19937_64 rng(20261124);
    std::uniform_real_distribution<double> step_k(-5e-3, 5e-3);
    SteppedLog ln_t;
    SteppedExp psat_exp, vaso_exp;
    double t_k = 307.0, worst_log = 0.0, worst_psat = 0.0, worst_vaso = 0.0;
    for (int i = 0; i < 200000; ++i) {
        t_k += step_k(rng);
        const double l = ln_t(t_k);
        worst_log = std::max(worst_log, relative_error(l, std::log(t_k)));
        const double arg = 77.3450 + 0.0057 * t_k - 7235.0 / t_k - 8.2 * l;
        worst_psat = std::max(worst_psat, relative_error(psat_exp(arg), std::exp(arg)));
        const double vaso_arg = (t_k - 307.0) * 0.69314718055994530942 / 30.0;
        worst_vaso = std::max(worst_vaso, relative_error(vaso_exp(vaso_arg), std::exp(vaso_arg)));
    }
    CHECK(worst_log < 1e-14);
    CHECK(worst_psat < 1e-14);
    CHECK(worst_vaso < 1e-14);
    // It is the library's value to about 1e-14, not bit for bit: the series really ran.
    CHECK(worst_psat > 0.0);
}

TEST_CASE("Stepped exp and log are exact on the first call and after a jump", "[thermoreg][stepwise]") {
    SteppedExp e;
    SteppedLog l;
    CHECK(e(1.5) == std::exp(1.5));
    CHECK(l(310.0) == std::log(310.0));
    CHECK(e(1.5 + 0.5) == std::exp(2.0));  // beyond the series' step limit: recomputed
    CHECK(l(320.0) == std::log(320.0));
    CHECK(e(-30.0) == std::exp(-30.0));
}
