#pragma once
// The manikin under a thermoregulation model's control (issue 34; docs/thermoregulation.md, "The
// manikin in the loop"). Every coupling period the loop gives the Stolwijk model each segment's
// measured heat loss (the manikin's zones mapped to the model's six segments by area), advances
// the model over the period, and commands every zone's skin setpoint and sweat rate from the
// model's skin temperatures and sweat. The daemon's limits are enforced here: setpoint bounds and
// rate, sweat bounds; and the loop falls back to constant skin temperature (the last setpoints
// held) with an alarm when the model diverges, a zone's measurement is stale or a zone cannot
// follow its setpoint. Pure logic: the daemon hands it readings and sends what it returns.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/zone_map.hpp"
#include "daemon/campaign_plan.hpp"
#include "daemon/config.hpp"
#include "physics/thermoreg/stolwijk.hpp"

namespace manikind {

// The latest of one zone's readings, as the daemon holds them.
struct LoopZoneReading {
    double skin_temp_c = 0.0;
    double heat_flux_w_m2 = 0.0;       // heat supplied = heat lost (positive), the manikin's convention
    std::int64_t flux_mono_ns = -1;    // when the flux was read; -1: never
    bool good = false;
    bool flagged = false;              // the manikin flags the zone (a heater or sensor fault)
};

struct LoopInputs {
    std::int64_t now_ns = 0;             // the lab's clock: virtual, real, or paced at --speed
    // How long the campaign has stood paused, in all, by the daemon's campaign state (never
    // guessed from a gap between ticks: a daemon that stalls, or ticks every 10 lab-seconds at
    // --speed 10, is not paused). The loop takes its increase between two ticks as paused time.
    std::int64_t paused_total_ns = 0;
    std::vector<LoopZoneReading> zones;  // zone 1 at index 0
    double air_temp_c = 0.0;             // the enclosure's measured air, RH, wall (the model's MRT), air speed
    double rh_pct = 0.0;
    double wall_temp_c = 0.0;
    double air_speed_m_s = 0.0;
};

struct ZoneCommand {
    int zone = 0;
    double skin_setpoint_c = 0.0;
    double sweat_rate_g_m2_h = 0.0;
};

struct LoopAlarm {
    std::string severity;  // "info", "warn", "error"
    std::string message;
};

struct LoopOutput {
    std::vector<ZoneCommand> commands;                          // send when not empty
    std::vector<std::pair<std::string, double>> model_channels; // record as device "model"
    std::vector<LoopAlarm> alarms;
    std::optional<ChamberPhase> chamber_change;                 // the protocol's next chamber setpoints
    bool fell_back = false;                                     // this tick: the trial is to be flagged
    bool finished = false;                                      // the model's duration is reached
};

class PhysiologicalLoop {
public:
    enum class Phase { preconditioning, running, fallback, finished };

    // Throws UserError when the segment map does not place every zone of `map` in exactly one
    // model segment, or a model segment gets no zone.
    PhysiologicalLoop(const PhysiologicalModel& model, const config::PhysiologicalConfig& config,
                      const analysis::ZoneMap& map);

    // Called every daemon tick (any rate); acts at most once per coupling period.
    LoopOutput tick(const LoopInputs& in);

    Phase phase() const { return phase_; }
    double model_time_s() const { return body_.time_s(); }
    // What the console and status show beside the zones.
    nlohmann::json status_json() const;
    // The model segment of each zone (index = zone - 1), for tests and docs.
    const std::vector<int>& zone_segments() const { return zone_segment_; }
    const std::vector<double>& zone_setpoints_c() const { return setpoint_c_; }  // last commanded, zone 1 first

private:
    void command_towards(const std::vector<double>& target_c, const std::vector<double>& sweat_g_m2_h, double dt_s,
                         LoopOutput& out);
    void fall_back(const std::string& why, LoopOutput& out);
    void record(const physics::thermoreg::StepState& st, const physics::thermoreg::SegmentValues& loss_w,
                const physics::thermoreg::Environment& env, LoopOutput& out);

    PhysiologicalModel model_;
    config::PhysiologicalConfig cfg_;
    analysis::ZoneMap map_;
    std::vector<int> zone_segment_;                 // model segment of each zone
    physics::thermoreg::SegmentValues segment_zone_area_m2_{};
    physics::thermoreg::Body body_;
    Phase phase_ = Phase::preconditioning;
    std::optional<std::int64_t> started_ns_;        // first tick
    std::optional<std::int64_t> last_tick_ns_;      // the latest tick's time, for status_json
    std::optional<std::int64_t> paused_seen_ns_;    // LoopInputs::paused_total_ns at the last tick
    std::optional<std::int64_t> last_command_ns_;
    std::optional<std::int64_t> running_since_ns_;  // the model's t = 0
    std::optional<std::int64_t> on_target_since_ns_;
    std::vector<double> initial_skin_c_;            // the model's skin at its start, per zone
    std::vector<double> setpoint_c_;                // last commanded, per zone
    std::vector<double> sweat_g_m2_h_;
    std::vector<std::optional<std::int64_t>> off_since_ns_;  // per zone: off its setpoint since
    std::vector<double> flux_sum_w_m2_;             // per zone: good readings since the last step
    std::vector<int> flux_count_;
    std::vector<std::int64_t> last_flux_ns_;
    std::size_t next_phase_ = 0;
    std::string fallback_reason_;
    static std::vector<double> skin_now(const LoopInputs& in);
    physics::thermoreg::SegmentValues last_loss_w_{};
    physics::thermoreg::SegmentValues last_shell_w_{};  // what warmed each segment's shell at the last step, W
    // Each zone's skin temperature at the last coupling step: the shell's storage over a step is
    // C (T_now - T_then) / dt (NaN where a reading was bad then).
    std::vector<double> skin_at_step_c_;
};

}  // namespace manikind
