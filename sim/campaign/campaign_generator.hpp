#pragma once
// Recorded campaigns from the simulated world, for proving reconcile and for demos: each trial
// is 75 min of 5-s samples with the manikin warming to its setpoint, sensor noise, replicate
// scatter and, now and then, a trial that never settles. The world's physics is a twin version
// (the baseline plus hidden terms); whoever reads the recordings is never told which.
#include <cstdint>
#include <string>
#include <vector>

#include "physics/twin/twin.hpp"
#include "sim/campaign/replicate_scatter.hpp"

namespace manikind::sim {

struct CampaignCase {
    int case_id = 0;
    double chamber_temp_c = 0.0;     // chamber setpoint (Table S3 T_c)
    double chamber_rh_pct = 0.0;     // chamber setpoint (Table S3 RH_c)
    double air_temp_c = 0.0;         // enclosure air it settles at (Table S3 T_air)
    double air_rh_pct = 0.0;         // (Table S3 RH_air)
    double skin_setpoint_c = 35.0;
    double wettedness = 0.0;
};

// Table S3: the paper's 15 validation cases (the default case list).
std::vector<CampaignCase> table_s3_cases();

struct ZoneSpec {
    physics::twin::ZoneInput zone;   // skin_temp_c is ignored: the setpoint drives it
    std::string name;
};

struct GeneratorOptions {
    physics::twin::TwinVersion world;       // hidden physics
    int replicates = 3;
    double duration_s = 4500.0;             // 75 min (Methods)
    double sample_period_s = 5.0;           // Text S3.2: every 5 s
    std::uint64_t seed = 1;
    double unsteady_probability = 0.0;      // chance a trial never settles
    double skin_time_constant_s = 300.0;    // shell warm-up lag under the manikin's PI control
    double skin_noise_c = 0.004;            // zone RTD noise (well inside the 0.05 °C rule)
    double flux_noise_w_m2 = 1.5;           // heat-flux sensor noise
    ReplicateScatter scatter;               // trial-to-trial scatter; ReplicateScatter::none() for exact tests
    double air_noise_c = 0.03;
    double rh_noise_pct = 0.3;
    double wall_below_air_c = 0.4;          // walls run a little cooler (Text S3.3)
    double air_speed_mean_m_s = 0.01;       // sealed enclosure: < 0.02 m/s (Text S3.1)
    std::int64_t start_epoch_s = 1780304400;  // 2026-06-01T09:00:00Z; trials follow 2 h apart
    // The probes' calibration errors, the same in every trial of the campaign (recorded minus
    // actual): a real lab's EE181s are off by a fixed amount within their specification. 0: exact.
    double probe_air_bias_c = 0.0;
    double probe_rh_bias_pct = 0.0;
    double probe_wall_bias_c = 0.0;
    // How the lab sets its enclosure. false: it settles at the case's T_air and RH_air whatever the
    // probes read (the probes record it off by their bias). true: the lab trims the chamber until
    // its own probes read the case's values, so the air really settles off them by the bias
    // (actual = nominal - bias): where its probes are wrong, its "isothermal" case is not.
    bool chamber_set_by_probes = false;
    // The manikin's heat-flux calibration error, the same in every trial: recorded = (1 + gain) q + offset.
    double flux_calibration_gain = 0.0;
    double flux_calibration_offset_w_m2 = 0.0;
};

// What one trial really was, kept for tests (the recordings never carry it).
struct TrialTruth {
    double air_temp_c = 0.0;                 // the enclosure's actual air, which the physics sees
    double air_rh_pct = 0.0;
    double wall_temp_c = 0.0;
    double probe_air_error_c = 0.0;          // recorded = actual + this + sensor noise
    double probe_rh_error_pct = 0.0;
    double probe_wall_error_c = 0.0;
    std::vector<double> zone_flux_factor;    // [zone] 1 + e, e ~ N(0, replicate_flux_rel_sd)
    std::vector<double> zone_flux_offset_w_m2;  // [zone] ~ N(0, replicate_flux_sd_w_m2)
};

struct GeneratedTrial {
    std::string id;                          // c09-r1
    int case_id = 0;
    int replicate = 0;
    CampaignCase conditions;
    std::string started_utc;
    bool unsteady = false;                   // generated to never settle (ground truth for tests)
    TrialTruth truth;
    std::vector<double> t_s, air_temp_c, air_rh_pct, air_speed_m_s, wall_temp_c;
    std::vector<std::vector<double>> skin_temp_c;     // [zone][sample]
    std::vector<std::vector<double>> heat_flux_w_m2;  // [zone][sample]
};

// Throws std::invalid_argument for non-physical options (no replicates, non-positive period, ...).
std::vector<GeneratedTrial> generate_campaign(const std::vector<CampaignCase>& cases, const std::vector<ZoneSpec>& zones,
                                              const GeneratorOptions& options);

// Parses an effect given on the command line: term:param=value[,param=value][:region=R][:zones=5,23]
// e.g. "humidity_buoyancy:gamma=146", "partial_wettedness:fraction=0.3:region=head",
// "heat_leak:q_w_m2=20:zones=5,23". Throws std::invalid_argument with what was expected.
physics::twin::Term parse_effect(const std::string& text);

}  // namespace manikind::sim
