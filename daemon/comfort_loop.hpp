#pragma once
// Comfort mode (issue 65; docs/daemon.md, "Comfort mode"): each zone's skin temperature is set
// from its own measured heat loss by a comfort equation, t_sk = a - b q, the mode ISO 14505-2
// prefers for equivalent temperature: a zone that loses more is held cooler, as a person's skin
// would be. Default coefficients a = 36.4 °C, b = 0.054 °C m²/W: the manikin comfort equation of
// Nilsson's thesis (2004, after Madsen); not checked against ISO 14505-2's text, which is not
// public; a campaign sets its own. Every coupling period each zone's setpoint moves towards
// a - b (its mean flux since the last step) at no more than the allowed rate, within the skin
// setpoint bounds ([physiological] max_setpoint_rate_c_min, min/max_skin_setpoint_c; [safety]
// still applies). The loss is the heaters' power less what warmed the shell (C dT_skin/dt, the
// [physiological] shell capacity), smoothed over kLossSmoothing_s: a setpoint step makes the
// heaters' power spike, and fed back raw that spike set the next target lower (on the simulated
// lab the zones never settled). Pure logic: the daemon hands it readings and sends what it returns.
#include <cstdint>
#include <optional>
#include <vector>

#include "analysis/zone_map.hpp"
#include "daemon/config.hpp"
#include "daemon/physiological_loop.hpp"

namespace manikind {

inline constexpr double kLossSmoothing_s = 300.0;  // ours: the loss's first-order smoothing

class ComfortLoop {
public:
    ComfortLoop(ComfortEquation eq, const config::PhysiologicalConfig& limits, const analysis::ZoneMap& map);
    // Called every daemon tick; returns the zones' new setpoints at most once per coupling period
    // (empty otherwise), the first time at once from each zone's own temperature.
    std::vector<ZoneCommand> tick(const LoopInputs& in);
    const std::vector<double>& zone_setpoints_c() const { return setpoint_c_; }
    // Each zone's comfort target at the last step (a - b q), NaN before one.
    const std::vector<double>& zone_targets_c() const { return target_c_; }
    const ComfortEquation& equation() const { return eq_; }

private:
    ComfortEquation eq_;
    config::PhysiologicalConfig limits_;
    std::size_t zones_ = 0;
    std::vector<int> zone_ids_;
    std::optional<std::int64_t> last_step_ns_;
    std::vector<double> setpoint_c_, target_c_, flux_sum_w_m2_, skin_then_c_, loss_w_m2_;
    std::vector<int> flux_count_;
    std::vector<std::int64_t> last_flux_ns_;
};

}  // namespace manikind
