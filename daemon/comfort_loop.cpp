#include "daemon/comfort_loop.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace manikind {

ComfortLoop::ComfortLoop(ComfortEquation eq, const config::PhysiologicalConfig& limits, const analysis::ZoneMap& map)
    : eq_(eq), limits_(limits), zones_(map.size()) {
    for (const auto& z : map.zones) zone_ids_.push_back(z.zone);
    setpoint_c_.assign(zones_, std::numeric_limits<double>::quiet_NaN());
    target_c_.assign(zones_, std::numeric_limits<double>::quiet_NaN());
    skin_then_c_.assign(zones_, std::numeric_limits<double>::quiet_NaN());
    loss_w_m2_.assign(zones_, std::numeric_limits<double>::quiet_NaN());
    flux_sum_w_m2_.assign(zones_, 0.0);
    flux_count_.assign(zones_, 0);
    last_flux_ns_.assign(zones_, -1);
}

std::vector<ZoneCommand> ComfortLoop::tick(const LoopInputs& in) {
    std::vector<ZoneCommand> out;
    if (in.zones.size() != zones_) return out;
    // Every good flux reading since the last step, averaged per zone.
    for (std::size_t z = 0; z < zones_; ++z) {
        const auto& r = in.zones[z];
        if (r.good && r.flux_mono_ns > last_flux_ns_[z] && std::isfinite(r.heat_flux_w_m2)) {
            flux_sum_w_m2_[z] += r.heat_flux_w_m2;
            ++flux_count_[z];
            last_flux_ns_[z] = r.flux_mono_ns;
        }
    }
    const auto period_ns = static_cast<std::int64_t>(limits_.coupling_period_s * 1e9);
    if (last_step_ns_ && in.now_ns - *last_step_ns_ < period_ns) return out;
    const double dt_s = last_step_ns_ ? static_cast<double>(in.now_ns - *last_step_ns_) * 1e-9 : 0.0;
    last_step_ns_ = in.now_ns;
    // At the allowed rate over the time since the last step, never more than two periods' worth.
    const double max_step_c = limits_.max_setpoint_rate_c_min / 60.0 * std::min(dt_s, 2.0 * limits_.coupling_period_s);
    for (std::size_t z = 0; z < zones_; ++z) {
        const auto& r = in.zones[z];
        if (!std::isfinite(setpoint_c_[z]))  // the first step: from the zone's own temperature, never a jump
            setpoint_c_[z] = r.good && std::isfinite(r.skin_temp_c) ? r.skin_temp_c : eq_.skin_c(0.0);
        const double skin_now = r.good && std::isfinite(r.skin_temp_c) ? r.skin_temp_c : std::numeric_limits<double>::quiet_NaN();
        if (flux_count_[z] > 0) {
            // The surface's loss: the heaters' power less the shell's storage over the step.
            double loss = flux_sum_w_m2_[z] / flux_count_[z];
            if (dt_s > 0.0 && std::isfinite(skin_now) && std::isfinite(skin_then_c_[z]))
                loss -= limits_.shell_heat_capacity_j_m2k * (skin_now - skin_then_c_[z]) / dt_s;
            const double w = std::isfinite(loss_w_m2_[z]) ? 1.0 - std::exp(-dt_s / kLossSmoothing_s) : 1.0;
            loss_w_m2_[z] = std::isfinite(loss_w_m2_[z]) ? loss_w_m2_[z] + w * (loss - loss_w_m2_[z]) : loss;
            target_c_[z] = eq_.skin_c(loss_w_m2_[z]);  // t_sk = a - b q
            const double target = std::clamp(target_c_[z], limits_.min_skin_setpoint_c, limits_.max_skin_setpoint_c);
            setpoint_c_[z] += std::clamp(target - setpoint_c_[z], -max_step_c, max_step_c);
        }
        setpoint_c_[z] = std::clamp(setpoint_c_[z], limits_.min_skin_setpoint_c, limits_.max_skin_setpoint_c);
        skin_then_c_[z] = skin_now;
        flux_sum_w_m2_[z] = 0.0;
        flux_count_[z] = 0;
        out.push_back({zone_ids_[z], setpoint_c_[z], 0.0});
    }
    return out;
}

}  // namespace manikind
