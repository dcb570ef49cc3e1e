#pragma once
// Steady-state detection (Text S3, "3.2 Experimental procedure"): a trial is steady when
// every zone's skin temperature stays within 0.05 °C (max - min) over the final 30 min.
// Optionally the heat flux must be stable too (drift of a least-squares line over the
// window, and scatter about it).
#include <string>
#include <vector>

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
    double max_flux_sd_w_m2 = 0.0;
    int worst_flux_sd_zone = 0;
};

SteadyStateResult detect_steady_state(const TrialData& data, const ZoneMap& map, const SteadyStateOptions& options = {});

}  // namespace manikind::analysis
