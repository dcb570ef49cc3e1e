// Steady-state rule (Text S3): every zone's skin temperature within 0.05 °C over the final
// 30 min. Synthetic traces (analysis/synthetic.hpp) with bounded uniform noise.
#include <cmath>
#include <limits>
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
