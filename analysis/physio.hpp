#pragma once
// Physiological trials' results (issue 34; docs/thermoregulation.md, "Results"): a trial run
// under the thermoregulation model's control has no steady state, so its result is trajectories:
// the model's core and mean skin temperature, the measured heat loss and the sweat, against the
// model's time, with 95 % bands. The bands come from replaying the model (physics/thermoreg) from
// what the trial recorded at every coupling step (each segment's measured loss and the enclosure
// conditions): Type B by Monte Carlo over the instruments' specifications (heat-flux gain common
// to all zones, offsets per zone, probe offsets per draw), Type A from the replicates of a case
// (GUM; Welch-Satterthwaite for k). The same replay without the manikin (the model's own
// exchange in the recorded conditions, coupled and temperature-only convection) shows what the
// measured exchange changed. Pure: works on an analysis::Campaign.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/recording.hpp"

namespace manikind::analysis::physio {

struct Options {
    int draws = 200;              // Monte Carlo draws for Type B
    std::uint64_t seed = 1;
};

struct Point {
    double t_s = 0.0;                       // the model's time
    double core_temp_c = 0.0, core_u95_c = 0.0;
    double mean_skin_temp_c = 0.0, mean_skin_u95_c = 0.0;
    double heat_loss_w = 0.0, heat_loss_u95_w = 0.0;   // measured, all segments (+ = lost)
    double sweat_rate_g_h = 0.0;
    double metabolic_w = 0.0, respiration_loss_w = 0.0, storage_w = 0.0;
    // The model alone in the recorded conditions (no manikin): coupled and temperature-only.
    double alone_coupled_core_c = 0.0, alone_coupled_skin_c = 0.0;
    double alone_dt_only_core_c = 0.0, alone_dt_only_skin_c = 0.0;
    // The model alone's own 95 % band from the probes' specifications (air, humidity, wall, air
    // speed: the conditions it was given are only as good as the probes), and the band of the
    // difference loop minus alone, from the same draws for both (the errors are shared): the
    // loop "agrees" with the model alone where |difference| is within it.
    double alone_core_u95_c = 0.0, alone_skin_u95_c = 0.0;
    double diff_core_u95_c = 0.0, diff_skin_u95_c = 0.0;
    // A case with replicates: the 95 % half-width about the replicates' mean within which a further
    // run on this manikin and chamber is expected (Type A across runs: t(n-1) s sqrt(1 + 1/n); the
    // instruments' calibration is shared by the runs, so no Type B). NaN with one replicate.
    double core_repro_u95_c = std::nan(""), skin_repro_u95_c = std::nan("");
};

// Where the loop agrees with the model alone in the recorded conditions: points whose difference
// (core and mean skin) lies within the difference's band.
struct Agreement {
    int points = 0, core_within = 0, skin_within = 0;
    double worst_skin_c = 0.0, worst_skin_u95_c = 0.0;  // the largest |difference| in mean skin, and its band there
    // At least 95 % of the steps within in both: each step's band is a 95 % band, so a loop that
    // behaves as the model alone still leaves about one step in twenty outside.
    bool agrees = false;
};

struct TrialTrajectory {
    std::string trial;
    int case_id = 0;
    int replicate = 0;
    double coupling_period_s = 0.0;
    double replay_max_abs_diff_c = 0.0;  // the replay against the recorded model state (a check)
    bool fell_back = false;              // the loop fell back to constant skin temperature
    std::vector<Point> points;
    Agreement agreement;
};

struct CaseTrajectory {
    int case_id = 0;
    int replicates = 0;
    std::vector<Point> points;  // mean over the replicates, U95 from Type A and B
    Agreement agreement;
};

struct Result {
    std::vector<TrialTrajectory> trials;
    std::vector<CaseTrajectory> cases;
};

// Trials without the model's channels are skipped; throws InputError when a trial's model
// channels are present but incomplete (a channel missing or not a number where time_s is).
Result compute(const Campaign& campaign, const Options& options = {});
nlohmann::json to_json(const Result& result);
// What the daemon stores with a campaign's results (key "physiological"): per case the replicates'
// trajectory a point a minute and its last point as "final".
nlohmann::json results_json(const Result& result);
// One line per case of that JSON, as `manikin results` and manikind print them.
std::string summary_text(const nlohmann::json& physiological);
// Fig. 4 from measured data: temperatures with bands (top), heat rates and sweat (bottom).
std::string svg(const Result& result, const std::string& title);

}  // namespace manikind::analysis::physio
