// Steady-state rule (Text S3): every zone's skin temperature within 0.05 °C over the final
// 30 min. Synthetic traces (analysis/synthetic.hpp) with bounded uniform noise.
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include <catch2/catch.hpp>

#include "analysis/steady_state.hpp"
#include "analysis/synthetic.hpp"

namespace an = manikind::analysis;

namespace {

const an::ZoneMap& map() { return an::andi35_zone_map(); }

an::SyntheticTrialOptions settling() {
    an::SyntheticTrialOptions o;
    o.skin_start_offset_c = -1.0;
    o.skin_time_constant_s = 300.0;  // exp(-2700/300) = 1.2e-4 °C left at the window start
    o.skin_noise_c = 0.01;           // range at most 0.02 °C
    return o;
}

// Drops the rows with t in (from_s, to_s).
void drop_rows(an::TrialData& d, double from_s, double to_s) {
    an::TrialData out = d;
    auto keep = [&](std::size_t i) { return !(d.t_s[i] > from_s && d.t_s[i] < to_s); };
    auto filter = [&](std::vector<double>& v, const std::vector<double>& src) {
        v.clear();
        for (std::size_t i = 0; i < src.size(); ++i)
            if (keep(i)) v.push_back(src[i]);
    };
    filter(out.t_s, d.t_s);
    filter(out.air_temp_c, d.air_temp_c);
    filter(out.air_rh_pct, d.air_rh_pct);
    filter(out.air_speed_m_s, d.air_speed_m_s);
    filter(out.wall_temp_c, d.wall_temp_c);
    for (std::size_t z = 0; z < d.skin_temp_c.size(); ++z) {
        filter(out.skin_temp_c[z], d.skin_temp_c[z]);
        filter(out.heat_flux_w_m2[z], d.heat_flux_w_m2[z]);
    }
    d = out;
}

}  // namespace

TEST_CASE("a trace that settles early is steady over the final 30 min") {
    const auto d = an::make_synthetic_trial(map(), settling());
    const auto r = an::detect_steady_state(d, map());
    CHECK(r.steady);
    CHECK(r.reason.empty());
    CHECK(r.window_start_s == Approx(4500.0 - 1800.0));
    CHECK(r.window_end_s == Approx(4500.0));
    CHECK(r.max_skin_fluctuation_c <= 2 * 0.01 + 2e-4);
    CHECK(r.max_skin_fluctuation_c > 0.0);
    CHECK(r.worst_zone >= 1);
    CHECK(r.settled_since_s < 2700.0);
}

TEST_CASE("a trace that never settles is flagged with its worst zone") {
    auto o = settling();
    o.skin_noise_c = 0.05;  // uniform ±0.05: the range over 361 samples is close to 0.1 °C
    const auto d = an::make_synthetic_trial(map(), o);
    const auto r = an::detect_steady_state(d, map());
    CHECK_FALSE(r.steady);
    CHECK(r.reason.find("never settled") != std::string::npos);
    CHECK(r.max_skin_fluctuation_c > 0.05);
    CHECK(r.max_skin_fluctuation_c <= 0.1 + 2e-4);
    // The reported worst zone really has the reported fluctuation.
    const auto& skin = d.skin_temp_c[static_cast<std::size_t>(r.worst_zone - 1)];
    double lo = 1e9, hi = -1e9;
    for (std::size_t i = 0; i < d.rows(); ++i)
        if (d.t_s[i] >= 2700.0) {
            lo = std::min(lo, skin[i]);
            hi = std::max(hi, skin[i]);
        }
    CHECK(r.max_skin_fluctuation_c == Approx(hi - lo));
}

TEST_CASE("a trace that settles late is not steady, and says since when it is settled") {
    auto o = settling();
    o.skin_time_constant_s = 1200.0;  // exp(-2700/1200) - exp(-4500/1200) = 0.082 °C over the window
    o.skin_noise_c = 0.002;
    const auto d = an::make_synthetic_trial(map(), o);
    const auto r = an::detect_steady_state(d, map());
    CHECK_FALSE(r.steady);
    CHECK(r.settled_since_s > 2700.0);
    CHECK(r.settled_since_s < 4500.0);
    CHECK(r.reason.find("only since") != std::string::npos);
    // A shorter window inside the settled tail is steady.
    an::SteadyStateOptions shorter;
    shorter.window_s = 4500.0 - r.settled_since_s;
    CHECK(an::detect_steady_state(d, map(), shorter).steady);
}

TEST_CASE("a single noisy zone makes the trial unsteady and is named") {
    auto d = an::make_synthetic_trial(map(), settling());
    auto& zone7 = d.skin_temp_c[6];
    for (std::size_t i = 0; i < d.rows(); ++i) zone7[i] += 0.04 * std::sin(d.t_s[i] / 60.0);  // ±0.04 °C wave
    const auto r = an::detect_steady_state(d, map());
    CHECK_FALSE(r.steady);
    CHECK(r.worst_zone == 7);
    CHECK(r.max_skin_fluctuation_c > 0.08 - 0.001);
    CHECK(r.reason.find("zone 07") != std::string::npos);
}

TEST_CASE("gaps: a short run of missing rows is tolerated, a long one is not") {
    auto d = an::make_synthetic_trial(map(), settling());
    drop_rows(d, 3000.0, 3040.0);  // 40 s without rows, limit 60 s
    CHECK(an::detect_steady_state(d, map()).steady);
    drop_rows(d, 3500.0, 3700.0);  // 200 s
    const auto r = an::detect_steady_state(d, map());
    CHECK_FALSE(r.steady);
    CHECK(r.reason.find("gap") != std::string::npos);
}

TEST_CASE("NaNs: scattered ones are skipped, a zone gone silent is not steady") {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    auto d = an::make_synthetic_trial(map(), settling());
    for (std::size_t i = 0; i < d.rows(); i += 7) d.skin_temp_c[2][i] = nan;  // every 35 s
    for (std::size_t i = 3; i < d.rows(); i += 11) d.heat_flux_w_m2[4][i] = nan;
    const auto r = an::detect_steady_state(d, map());
    CHECK(r.steady);
    CHECK(std::isfinite(r.max_skin_fluctuation_c));
    for (std::size_t i = 0; i < d.rows(); ++i)
        if (d.t_s[i] > 3600.0) d.skin_temp_c[2][i] = nan;  // zone 3 silent for the last 15 min
    const auto r2 = an::detect_steady_state(d, map());
    CHECK_FALSE(r2.steady);
    CHECK(r2.reason.find("zone 03") != std::string::npos);
}

TEST_CASE("partial and empty trials are not steady and say why") {
    auto o = settling();
    o.duration_s = 1200.0;  // 20 min < 30 min window
    const auto r = an::detect_steady_state(an::make_synthetic_trial(map(), o), map());
    CHECK_FALSE(r.steady);
    CHECK(r.reason.find("partial") != std::string::npos);
    an::TrialData empty;
    empty.skin_temp_c.resize(map().size());
    empty.heat_flux_w_m2.resize(map().size());
    const auto e = an::detect_steady_state(empty, map());
    CHECK_FALSE(e.steady);
    CHECK(e.reason.find("empty") != std::string::npos);
}

TEST_CASE("window length and tolerance are configurable") {
    auto o = settling();
    o.skin_noise_c = 0.03;  // range up to 0.06 °C
    const auto d = an::make_synthetic_trial(map(), o);
    an::SteadyStateOptions loose;
    loose.max_skin_fluctuation_c = 0.07;
    CHECK(an::detect_steady_state(d, map(), loose).steady);
    an::SteadyStateOptions strict;
    strict.max_skin_fluctuation_c = 0.04;
    CHECK_FALSE(an::detect_steady_state(d, map(), strict).steady);
    an::SteadyStateOptions ten_min;
    ten_min.window_s = 600.0;
    CHECK(an::detect_steady_state(d, map(), ten_min).window_start_s == Approx(3900.0));
}

TEST_CASE("flux stability: a drifting flux fails only when required") {
    auto d = an::make_synthetic_trial(map(), settling());
    for (auto& zone : d.heat_flux_w_m2)
        for (std::size_t i = 0; i < d.rows(); ++i) zone[i] += 0.002 * d.t_s[i];  // 3.6 W/m² over 30 min
    an::SteadyStateOptions o;
    const auto plain = an::detect_steady_state(d, map(), o);
    CHECK(plain.steady);
    CHECK(plain.max_flux_drift_w_m2 == Approx(0.002 * 1800.0).margin(0.3));
    o.require_flux_stability = true;
    const auto strict = an::detect_steady_state(d, map(), o);
    CHECK_FALSE(strict.steady);
    CHECK(strict.reason.find("drifts") != std::string::npos);
    // Scatter: the synthetic flux noise is uniform ±0.5 -> SD 0.5/sqrt(3) = 0.29 W/m².
    CHECK(plain.max_flux_sd_w_m2 == Approx(0.5 / std::sqrt(3.0)).margin(0.05));
    o.max_flux_drift_w_m2 = 10.0;
    o.max_flux_sd_w_m2 = 0.1;
    const auto noisy = an::detect_steady_state(d, map(), o);
    CHECK_FALSE(noisy.steady);
    CHECK(noisy.reason.find("scatters") != std::string::npos);
}

TEST_CASE("Text S3: a 0.04 °C/30 min drift with 0.005 °C noise passes the 0.05 °C range rule, the slope finds it") {
    an::SyntheticTrialOptions o;
    o.skin_start_offset_c = 0.0;  // settled from the start: only drift and noise
    o.skin_noise_c = 0.005;       // uniform in ±0.005 °C
    auto d = an::make_synthetic_trial(map(), o);
    const double drift_c_per_s = 0.04 / 1800.0;
    for (auto& zone : d.skin_temp_c)
        for (std::size_t i = 0; i < zone.size(); ++i) zone[i] += drift_c_per_s * d.t_s[i];
    const auto r = an::detect_steady_state(d, map());
    // The paper's rule sees nothing wrong: 0.04 °C of trend + at most 0.01 °C of noise.
    CHECK(r.steady);
    CHECK(r.max_skin_fluctuation_c <= 0.05);
    REQUIRE(r.zone_skin.size() == map().size());
    for (const auto& z : r.zone_skin) {
        CHECK(z.samples == 361);
        CHECK(z.range_c <= 0.05);
        // The slope recovers the trend: within 4 standard uncertainties of 0.04 °C/30 min (35
        // zones at 4 u: a false failure has a chance of about 0.2 %)...
        CHECK(std::fabs(z.drift_c_per_30min - 0.04) <= 4.0 * z.u_drift_c_per_30min);
        // ...and is far from zero (white noise: u ≈ 0.0029 / sqrt(361 x 1800²/12) x 1800).
        CHECK(z.drift_c_per_30min / z.u_drift_c_per_30min > 10.0);
        CHECK(z.u_drift_c_per_30min < 0.002);
    }
    CHECK(r.max_skin_drift_c_per_30min == Approx(0.04).margin(4.0 * r.u_max_skin_drift_c_per_30min));
    CHECK(r.worst_skin_drift_zone >= 1);
}

TEST_CASE("without a drift the slope is consistent with zero, and the range is noise alone") {
    an::SyntheticTrialOptions o;
    o.skin_start_offset_c = 0.0;
    o.skin_noise_c = 0.005;
    const auto r = an::detect_steady_state(an::make_synthetic_trial(map(), o), map());
    CHECK(r.steady);
    int beyond_3u = 0;
    for (const auto& z : r.zone_skin) {
        CHECK(z.range_c <= 0.01);
        if (std::fabs(z.drift_c_per_30min) > 3.0 * z.u_drift_c_per_30min) ++beyond_3u;
    }
    CHECK(beyond_3u <= 1);  // 35 zones at 3 u: about 0.1 expected by chance
}

TEST_CASE("autocorrelated residuals inflate the drift's standard uncertainty") {
    // Slowly wandering skin temperature (an AR(1) trace, phi = 0.9):
    // positive lag-1 autocorrelation, so the white-noise formula would understate u.
    an::SyntheticTrialOptions o;
    o.skin_start_offset_c = 0.0;
    o.skin_noise_c = 0.005;
    auto d = an::make_synthetic_trial(map(), o);
    for (auto& zone : d.skin_temp_c) {
        double ar = 0.0;
        for (std::size_t i = 0; i < zone.size(); ++i) {
            ar = 0.9 * ar + (zone[i] - 35.0);  // AR(1) filter of the generator's white noise
            zone[i] = 35.0 + 0.3 * ar;
        }
    }
    const auto r = an::detect_steady_state(d, map());
    const auto& z = r.zone_skin.at(0);
    CHECK(z.lag1_autocorrelation > 0.7);
    // u = white-noise u x sqrt((1 + r1)/(1 - r1)); the white-noise u is s_res / sqrt(Stt).
    double mean_t = 0.0, stt = 0.0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < d.t_s.size(); ++i)
        if (d.t_s[i] >= r.window_start_s - 1e-6) { mean_t += d.t_s[i]; ++n; }
    mean_t /= static_cast<double>(n);
    for (std::size_t i = 0; i < d.t_s.size(); ++i)
        if (d.t_s[i] >= r.window_start_s - 1e-6) stt += (d.t_s[i] - mean_t) * (d.t_s[i] - mean_t);
    const double white_u = z.residual_sd_c / std::sqrt(stt) * 1800.0;
    const double r1 = z.lag1_autocorrelation;
    CHECK(z.u_drift_c_per_30min == Approx(white_u * std::sqrt((1.0 + r1) / (1.0 - r1))));
    CHECK(z.u_drift_c_per_30min > 2.0 * white_u);
}

TEST_CASE("Text S3 range rule with Gaussian noise of SD 0.005 °C: the range is mostly noise, the slope is not") {
    an::SyntheticTrialOptions o;
    o.skin_start_offset_c = 0.0;
    o.skin_noise_c = 0.0;  // Gaussian noise added below
    const auto clean = an::make_synthetic_trial(map(), o);
    std::mt19937 rng(7);
    std::normal_distribution<double> noise_c(0.0, 0.005);
    auto noisy = [&](double drift_c_per_30min) {
        auto d = clean;
        for (auto& zone : d.skin_temp_c)
            for (std::size_t i = 0; i < zone.size(); ++i) zone[i] += drift_c_per_30min * d.t_s[i] / 1800.0 + noise_c(rng);
        return an::detect_steady_state(d, map());
    };
    // Noise alone: 361 samples span about 5-7 SD per zone, the worst of 35 zones about
    // 0.033-0.039 °C (docs/analysis.md): most of the 0.05 °C budget, with no trend at all.
    const auto still = noisy(0.0);
    CHECK(still.steady);
    CHECK(still.max_skin_fluctuation_c > 0.028);
    CHECK(still.max_skin_fluctuation_c < 0.045);
    for (const auto& z : still.zone_skin) CHECK(z.range_c > 0.015);
    // With Gaussian noise a 0.04 °C/30 min drift no longer passes the range rule, but the
    // slope still recovers it.
    const auto drifting = noisy(0.04);
    CHECK_FALSE(drifting.steady);
    CHECK(drifting.max_skin_fluctuation_c > 0.05);
    for (const auto& z : drifting.zone_skin) {
        CHECK(std::fabs(z.drift_c_per_30min - 0.04) <= 4.0 * z.u_drift_c_per_30min);  // 35 zones at 4 u
        CHECK(z.drift_c_per_30min / z.u_drift_c_per_30min > 10.0);
    }
}
