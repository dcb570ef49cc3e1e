#pragma once
// Steady-state detection (Text S3, "3.2 Experimental procedure"): a trial is steady when
// every zone's skin temperature stays within 0.05 °C (max - min) over the final 30 min.
// Optionally the heat flux must be stable too (drift of a least-squares line over the
// window, and scatter about it).
#include <cstddef>
#include <string>
#include <vector>

#include "analysis/heat_loss_steady.hpp"
#include "analysis/recording.hpp"

namespace manikind::analysis {

struct SteadyStateOptions {
    double window_s = 1800.0;                // the final 30 min (Text S3)
    double max_skin_fluctuation_c = 0.05;    // max - min per zone over the window (Text S3)
    // Longest stretch in the window without a finite sample of a zone (missing rows, empty
    // cells, NaN); longer gaps mean the window is not observed and the trial is not steady.
    double max_gap_s = 60.0;
    // Flux stability (off by default; the paper judges by skin temperature only).
    bool require_flux_stability = false;
    double max_flux_drift_w_m2 = 2.0;        // |slope| x window length, per zone
    double max_flux_sd_w_m2 = 5.0;           // residual standard deviation about the line, per zone
    // The clothing standards' rule (analysis/heat_loss_steady.hpp): the whole-body heat loss and
    // the mean skin temperature steady over the window. `manikin clothing` requires it; its
    // window is this struct's window_s.
    bool require_heat_loss_stability = false;
    HeatLossRule heat_loss;
};

// A zone's skin temperature over the window: the paper's range and, beside it, the drift
// (least-squares slope). The range of n noisy samples grows with the noise (about 5-7 SD of
// Gaussian noise for 361 samples) and says little about a slow trend; the slope separates the two.
inline constexpr double kDriftInterval_s = 1800.0;  // drifts are reported per 30 min (Text S3 window)

struct ZoneSkinDrift {
    int zone = 0;
    std::size_t samples = 0;                 // finite samples in the window
    double range_c = 0.0;                    // max - min over the window (the paper's rule)
    // Least-squares slope x 30 min, °C per 30 min (NaN with fewer than 3 samples).
    double drift_c_per_30min = 0.0;
    // Standard uncertainty of the slope, °C per 30 min: s_res / sqrt(sum (t - t̄)²), inflated by
    // sqrt((1 + r1) / (1 - r1)) when the residuals' lag-1 autocorrelation r1 is positive
    // (AR(1) residuals, large-n approximation; r1 capped at 0.999); r1 <= 0 is treated as
    // white noise.
    double u_drift_c_per_30min = 0.0;
    double residual_sd_c = 0.0;              // scatter about the line
    double lag1_autocorrelation = 0.0;       // r1 of the residuals
};

struct SteadyStateResult {
    bool steady = false;
    std::string reason;                      // why not (empty when steady)
    double window_start_s = 0.0;             // the window judged: [end - window, end]
    double window_end_s = 0.0;
    double max_skin_fluctuation_c = 0.0;     // worst zone's max - min over the window
    int worst_zone = 0;                      // zone number (0 when there are no samples)
    // Earliest time from which every zone stays within the tolerance to the end of the
    // recording (a trial that settles late shows how late); NaN when not even the last
    // sample pair qualifies.
    double settled_since_s = 0.0;
    // Flux statistics over the window (always computed, gated by require_flux_stability).
    double max_flux_drift_w_m2 = 0.0;
    int worst_flux_drift_zone = 0;
    // Every zone's |slope| x window (the map's order; 0 where it has too few samples): reconcile
    // leaves a drifting zone's points out of its fit (a finding about the measurement).
    std::vector<double> zone_flux_drift_w_m2;
    // The whole-body heat loss over the window (always judged; gated by require_heat_loss_stability).
    HeatLossVerdict heat_loss;
    double max_flux_sd_w_m2 = 0.0;
    int worst_flux_sd_zone = 0;
    // Skin-temperature drift over the window, per zone (reported, never gated), and the zone
    // with the largest |drift| (0 when no zone has one).
    std::vector<ZoneSkinDrift> zone_skin;
    double max_skin_drift_c_per_30min = 0.0;   // signed drift of the worst zone
    double u_max_skin_drift_c_per_30min = 0.0;
    int worst_skin_drift_zone = 0;
};

SteadyStateResult detect_steady_state(const TrialData& data, const ZoneMap& map, const SteadyStateOptions& options = {});

}  // namespace manikind::analysis
