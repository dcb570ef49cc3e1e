#include "sim/world/world.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace manikind::sim {

namespace mc = protocol::manikin_can;

World::World(WorldOptions options)
    : o_(std::move(options)), rng_(o_.seed), scatter_rng_(o_.seed ^ 0x5CA77E1200000001ULL) {
    if (o_.zones.empty()) throw std::invalid_argument("the simulated manikin needs a zone map");
    o_.scatter.validate();
    chamber_sp_c_ = chamber_air_c_ = air_c_ = o_.initial_temp_c;
    chamber_sp_rh_ = chamber_rh_ = rh_ = o_.initial_rh_pct;
    wall_c_ = air_c_ - o_.wall_below_air_c;
    zones_.resize(o_.zones.size());
    for (auto& z : zones_) z.skin_temp_c = o_.initial_temp_c;
    for (const auto& spec : o_.zones) conditions_.zones.push_back(spec.zone);
    if (!o_.local.empty()) {
        if (o_.local.size() != o_.zones.size()) throw std::invalid_argument("the simulated room's local environment: one entry per zone, or none");
        for (std::size_t z = 0; z < o_.zones.size(); ++z) conditions_.zones[z].local = o_.local[z];
    }
    scatter_.trial = 0;
    draw_trial_scatter();
}

void World::draw_trial_scatter() {
    const ReplicateScatter& sc = o_.scatter;
    std::normal_distribution<double> n(0.0, 1.0);
    auto draw = [&](double sd) { return sd * n(scatter_rng_); };  // drawn even at sd 0: same stream either way
    TrialScatter t;
    t.trial = scatter_.trial + 1;
    t.air_error_c = draw(sc.replicate_air_sd_c);
    t.rh_error_pct = draw(sc.replicate_rh_sd_pct);
    t.wall_error_c = draw(sc.replicate_wall_sd_c);
    for (int p = 0; p < max_probes; ++p) {
        t.probe_air_error_c.push_back(draw(sc.probe_air_sd_c));
        t.probe_rh_error_pct.push_back(draw(sc.probe_rh_sd_pct));
        t.probe_wall_error_c.push_back(draw(sc.probe_wall_sd_c));
    }
    for (std::size_t z = 0; z < zones_.size(); ++z) {
        t.zone_flux_factor.push_back(1.0 + draw(sc.replicate_flux_rel_sd));
        t.zone_flux_offset_w_m2.push_back(draw(sc.replicate_flux_sd_w_m2));
    }
    scatter_ = std::move(t);
}

std::size_t World::probe_index(int probe) {
    return static_cast<std::size_t>(std::clamp(probe, 1, max_probes) - 1);
}

void World::set_chamber_setpoints(double temp_c, double rh_pct) {
    chamber_sp_c_ = temp_c;
    chamber_sp_rh_ = rh_pct;
    apply_enclosure_offsets();
}

void World::apply_enclosure_offsets() {
    air_offset_c_ = rh_offset_pct_ = 0.0;
    for (const auto& c : o_.enclosure_table)
        if (std::abs(c.chamber_temp_c - chamber_sp_c_) <= 0.5 && std::abs(c.chamber_rh_pct - chamber_sp_rh_) <= 1.0) {
            air_offset_c_ = c.air_temp_c - c.chamber_temp_c;
            rh_offset_pct_ = c.air_rh_pct - c.chamber_rh_pct;
            return;
        }
}

bool World::set_room(const std::vector<physics::twin::LocalEnvironment>& room) {
    if (!room.empty() && room.size() != conditions_.zones.size()) return false;
    for (std::size_t z = 0; z < conditions_.zones.size(); ++z)
        conditions_.zones[z].local = !room.empty() ? room[z] : o_.local.empty() ? physics::twin::LocalEnvironment{} : o_.local[z];
    return true;
}

void World::wear(std::vector<physics::twin::Term> clothing) {
    clothing_ = std::move(clothing);
    dressed_ = o_.physics;
    dressed_.terms.insert(dressed_.terms.end(), clothing_.begin(), clothing_.end());
}

void World::step(double dt_s) {
    // Sub-steps keep the explicit PI/shell integration stable for any requested dt.
    const int n = std::max(1, static_cast<int>(std::ceil(dt_s / 1.0)));
    const double h = dt_s / n;
    for (int i = 0; i < n; ++i) {
        time_s_ += h;
        auto lag = [h](double& x, double target, double tau) { x += (target - x) * (1.0 - std::exp(-h / tau)); };
        lag(chamber_air_c_, chamber_sp_c_, o_.chamber_time_constant_s);
        lag(chamber_rh_, chamber_sp_rh_, o_.chamber_time_constant_s);
        // The enclosure settles where it actually does this trial: nominal offset plus the trial's error.
        lag(air_c_, chamber_air_c_ + air_offset_c_ + scatter_.air_error_c, o_.enclosure_time_constant_s);
        lag(rh_, std::clamp(chamber_rh_ + rh_offset_pct_ + scatter_.rh_error_pct, 0.0, 100.0), o_.enclosure_time_constant_s);
        lag(wall_c_, air_c_ - o_.wall_below_air_c + scatter_.wall_error_c, o_.wall_time_constant_s);

        if (run_ && time_s_ - last_heartbeat_s_ > o_.watchdog_s) watchdog_tripped_ = true;
        const bool heating = run_ && !watchdog_tripped_;

        // Heat loss of every zone at its current skin temperature (the world's physics).
        conditions_.air_temp_c = air_c_;
        conditions_.air_rh_pct = rh_;
        conditions_.wall_temp_c = wall_c_;
        conditions_.air_speed_m_s = o_.air_speed_m_s;
        bool any_wet = false, any_metered = false;
        for (std::size_t z = 0; z < zones_.size(); ++z) {
            conditions_.zones[z].skin_temp_c = zones_[z].skin_temp_c;
            any_wet = any_wet || (zones_[z].sweating && heating && !zones_[z].metered);
            any_metered = any_metered || zones_[z].metered;
        }
        conditions_.wettedness = any_wet ? 1.0 : 0.0;
        const auto& physics = clothing_.empty() ? o_.physics : dressed_;
        conditions_.zone_wettedness.clear();
        if (any_metered) {
            // Metered zones evaporate their supply up to what the air takes: w = supply / E_max.
            // E_max = q_e(w) / w (Eq. 1 is linear in w at a given h, and h carries w's own
            // buoyancy, Eq. 7): three passes of the fixed point from w = 1.
            auto& w = conditions_.zone_wettedness;
            w.assign(zones_.size(), conditions_.wettedness);
            for (std::size_t z = 0; z < zones_.size(); ++z)
                if (zones_[z].metered) w[z] = zones_[z].sweating && heating && zones_[z].sweat_rate_g_m2_h > 0.0 ? 1.0 : 0.0;
            for (int pass = 0; pass < 3; ++pass) {
                const auto at_w = physics::twin::predict(physics, conditions_);
                for (std::size_t z = 0; z < zones_.size(); ++z) {
                    if (!zones_[z].metered || w[z] == 0.0) continue;
                    const double supply_w_m2 = zones_[z].sweat_rate_g_m2_h * 2430.0 / 3600.0;  // latent heat 2430 J/g
                    const double e_max_w_m2 = at_w[z].q_evaporation_w_m2 / w[z];
                    w[z] = e_max_w_m2 > 0.0 ? std::clamp(supply_w_m2 / e_max_w_m2, 1e-6, 1.0) : 1.0;
                }
            }
        }
        for (std::size_t z = 0; z < zones_.size(); ++z)
            zones_[z].wettedness = conditions_.zone_wettedness.empty() ? conditions_.wettedness : conditions_.zone_wettedness[z];
        const auto fluxes = physics::twin::predict(physics, conditions_);
        for (std::size_t z = 0; z < zones_.size(); ++z) {
            ZoneState& s = zones_[z];
            // This replicate's fit and wetting change the heat transfer itself; the PI loop pays for it.
            s.loss_w_m2 = fluxes[z].q_total_w_m2 * scatter_.zone_flux_factor[z] + scatter_.zone_flux_offset_w_m2[z];
            double power = 0.0;
            if (heating && !s.heater_failed) {
                if (s.mode == mc::ControlMode::constant_skin_temp) {
                    const double error = s.setpoint - s.skin_temp_c;
                    const double max_p = o_.max_heater_power_w_m2;
                    const double unclamped = o_.pi_kp_w_m2k * error + s.integral_w_m2;
                    // Anti-windup: integrate only while the output is not saturated.
                    if (std::abs(unclamped) < max_p) s.integral_w_m2 += o_.pi_ki_w_m2ks * error * h;
                    // Negative power: the zone's coolant loop extracting heat (hot, dry cases).
                    power = std::clamp(o_.pi_kp_w_m2k * error + s.integral_w_m2, -max_p, max_p);
                } else if (s.mode == mc::ControlMode::constant_heat_flux) {
                    power = std::clamp(s.setpoint, -o_.max_heater_power_w_m2, o_.max_heater_power_w_m2);
                }
            }
            s.heater_power_w_m2 = power;
            s.skin_temp_c += h * (power - s.loss_w_m2) / o_.shell_heat_capacity_j_m2k;
        }
    }
}

// Recorded = actual + the probe's error this trial + noise.
double World::measure_air_temp_c(int probe) {
    return air_c_ + 0.02 * (probe - 1) + scatter_.probe_air_error_c[probe_index(probe)] + gauss(o_.air_noise_c);
}
double World::measure_rh_pct(int probe) {
    return std::clamp(rh_ + scatter_.probe_rh_error_pct[probe_index(probe)] + gauss(o_.rh_noise_pct), 0.0, 100.0);
}
double World::measure_wall_temp_c(int thermocouple) {
    return wall_c_ + scatter_.probe_wall_error_c[probe_index(thermocouple)] + gauss(o_.wall_noise_c);
}
double World::measure_air_speed_m_s() { return std::max(0.0, o_.air_speed_m_s + gauss(o_.speed_noise_m_s)); }

void World::manikin_command(const mc::Setpoint& sp) {
    auto apply = [&](ZoneState& z) {
        z.mode = sp.mode;
        z.setpoint = sp.value;
        z.sweating = sp.sweating;
        z.sweat_rate_g_m2_h = sp.sweating ? sp.sweat_rate_g_m2_h : 0.0;
        z.metered = sp.zone != 0;
    };
    if (sp.zone == 0) {
        for (auto& z : zones_) apply(z);
    } else if (sp.zone >= 1 && sp.zone <= zone_count()) {
        apply(zones_[static_cast<std::size_t>(sp.zone - 1)]);
    }
}

void World::manikin_control(bool run) {
    if (run && !run_) {
        watchdog_tripped_ = false;
        for (auto& z : zones_) z.integral_w_m2 = 0.0;
    }
    if (!run && run_) draw_trial_scatter();  // this trial is over; the next one scatters afresh
    run_ = run;
    last_heartbeat_s_ = time_s_;
    if (!run) watchdog_tripped_ = false;
}

mc::ZoneStatus World::measure_zone(int zone) {
    const ZoneState& s = this->zone(zone);
    mc::ZoneStatus st;
    st.zone = zone;
    st.skin_temp_c = s.skin_temp_c + gauss(o_.skin_noise_c);
    // The manikin reports the electrical power it needs to hold the zone as its heat flux.
    st.heater_power_w_m2 = std::max(0.0, s.heater_power_w_m2);
    st.heat_flux_w_m2 = s.heater_power_w_m2 + gauss(o_.flux_noise_w_m2);
    st.sweat_rate_g_m2_h = s.sweating ? s.sweat_rate_g_m2_h : 0.0;
    st.flags = 0;
    if (s.heater_power_w_m2 > 0.0) st.flags |= mc::heater_on;
    if (s.sweating) st.flags |= mc::sweating_on;
    if (s.heater_failed) st.flags |= mc::heater_fault;
    return st;
}

void World::fail_heater(int zone, bool failed) {
    if (zone >= 1 && zone <= zone_count()) zones_[static_cast<std::size_t>(zone - 1)].heater_failed = failed;
}

}  // namespace manikind::sim
