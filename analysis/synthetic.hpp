#pragma once
// Synthetic trials for tests, benchmarks and demos: skin temperature approaching its setpoint
// exponentially, heat flux settling to a chosen value, bounded (uniform) noise so a test
// knows the largest fluctuation it can see. Deterministic for a given seed.
#include <vector>

#include "analysis/recording.hpp"

namespace manikind::analysis {

struct SyntheticTrialOptions {
    double duration_s = 4500.0;              // 75 min (Text S3)
    double sample_interval_s = 5.0;          // every 5 s (Text S3)
    double air_temp_c = 39.6;
    double air_rh_pct = 38.3;
    bool with_air_speed = true;
    double air_speed_m_s = 0.02;
    bool with_wall_temp = true;
    double wall_temp_c = 39.2;
    double skin_temp_c = 35.0;               // setpoint the skin settles to
    double skin_start_offset_c = -1.0;       // skin - setpoint at t = 0
    double skin_time_constant_s = 300.0;     // exp(-t/tau) approach
    double skin_noise_c = 0.01;              // uniform in ±this
    double flux_w_m2 = -10.0;                // settled flux of every zone (unless zone_flux_w_m2)
    std::vector<double> zone_flux_w_m2;      // per zone, overrides flux_w_m2
    double flux_start_offset_w_m2 = 20.0;    // decays with the skin's time constant
    double flux_noise_w_m2 = 0.5;            // uniform in ±this
    unsigned seed = 1;
};

TrialData make_synthetic_trial(const ZoneMap& map, const SyntheticTrialOptions& options);

// A campaign of `cases` x `replicates` synthetic trials (ids cNN-rM) with the andi35 map;
// case c has air temperature 35 + c/2 °C (cycling every 60 cases, so at most 65 °C) and a
// flux that depends on the zone and the case.
Campaign make_synthetic_campaign(int cases, int replicates, const SyntheticTrialOptions& base = {});

}  // namespace manikind::analysis
