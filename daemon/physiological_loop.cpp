#include "daemon/physiological_loop.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <fmt/core.h>

#include "base/user_error.hpp"

namespace manikind {

namespace tr = physics::thermoreg;

namespace {
// Preconditioning is done when every zone has been within this of the model's initial skin
// temperature for this long (the model then starts from the state the manikin is in).
constexpr double precondition_band_c = 0.2;
constexpr double precondition_hold_s = 120.0;
// Preconditioning that has not reached the model's start after follow_timeout_s plus this much
// unpaused lab time falls back.
constexpr double precondition_limit_extra_s = 3600.0;

int model_segment_index(const std::string& name) {
    const auto& names = tr::segment_names();
    for (int i = 0; i < tr::segment_count; ++i)
        if (name == names[static_cast<std::size_t>(i)]) return i;
    return -1;
}
}  // namespace

PhysiologicalLoop::PhysiologicalLoop(const PhysiologicalModel& model, const config::PhysiologicalConfig& config,
                                     const analysis::ZoneMap& map)
    : model_(model), cfg_(config), map_(map), body_(model.metabolic_met, [] {
          tr::ModelOptions o;
          o.convection = tr::ConvectionModel::coupled;  // only for the model's own sweat ceiling estimate
          o.clo = 0.0;  // whatever the manikin wears is in its measured losses, not in the model
          return o;
      }()) {
    zone_segment_.assign(map_.size(), -1);
    for (const auto& [model_segment, zone_segments] : cfg_.segments) {
        const int m = model_segment_index(model_segment);
        if (m < 0) throw UserError(fmt::format("physiological.segments.{}: not a model segment", model_segment));
        for (std::size_t z = 0; z < map_.size(); ++z)
            if (std::find(zone_segments.begin(), zone_segments.end(), map_.zones[z].segment) != zone_segments.end()) {
                if (zone_segment_[z] >= 0)
                    throw UserError(fmt::format("physiological.segments: zone {} ({}, segment {}) is in two model segments",
                                                map_.zones[z].zone, map_.zones[z].name, map_.zones[z].segment));
                zone_segment_[z] = m;
            }
    }
    for (std::size_t z = 0; z < map_.size(); ++z) {
        if (zone_segment_[z] < 0)
            throw UserError(fmt::format("physiological.segments: zone {} ({}, zone-map segment '{}') is in no model segment",
                                        map_.zones[z].zone, map_.zones[z].name, map_.zones[z].segment));
        segment_zone_area_m2_[static_cast<std::size_t>(zone_segment_[z])] += map_.zones[z].area_m2;
    }
    for (int m = 0; m < tr::segment_count; ++m)
        if (!(segment_zone_area_m2_[static_cast<std::size_t>(m)] > 0.0))
            throw UserError(fmt::format("physiological.segments.{}: no zone of the zone map is in it",
                                        tr::segment_names()[static_cast<std::size_t>(m)]));
    // The model's initial skin temperature per zone (its set points): what preconditioning reaches.
    const auto nodes = body_.node_temps_c();
    for (std::size_t z = 0; z < map_.size(); ++z)
        initial_skin_c_.push_back(nodes[static_cast<std::size_t>(4 * zone_segment_[z] + 3)]);
    setpoint_c_.assign(map_.size(), 0.0);
    sweat_g_m2_h_.assign(map_.size(), 0.0);
    off_since_ns_.assign(map_.size(), std::nullopt);
    flux_sum_w_m2_.assign(map_.size(), 0.0);
    flux_count_.assign(map_.size(), 0);
    last_flux_ns_.assign(map_.size(), -1);
}

void PhysiologicalLoop::command_towards(const std::vector<double>& target_c, const std::vector<double>& sweat_g_m2_h,
                                        double dt_s, LoopOutput& out) {
    // At the allowed rate over the lab time since the last command, but never more than two
    // coupling periods' worth at once: after a long stall of the daemon (the zones held their
    // setpoints meanwhile) the setpoints go on at the rate, they do not jump to the model.
    const double max_step_c = cfg_.max_setpoint_rate_c_min / 60.0 * std::min(dt_s, 2.0 * cfg_.coupling_period_s);
    for (std::size_t z = 0; z < map_.size(); ++z) {
        const double target = std::clamp(target_c[z], cfg_.min_skin_setpoint_c, cfg_.max_skin_setpoint_c);
        setpoint_c_[z] += std::clamp(target - setpoint_c_[z], -max_step_c, max_step_c);
        setpoint_c_[z] = std::clamp(setpoint_c_[z], cfg_.min_skin_setpoint_c, cfg_.max_skin_setpoint_c);
        sweat_g_m2_h_[z] = std::clamp(std::isfinite(sweat_g_m2_h[z]) ? sweat_g_m2_h[z] : 0.0, 0.0, cfg_.max_sweat_rate_g_m2_h);
        out.commands.push_back({map_.zones[z].zone, setpoint_c_[z], sweat_g_m2_h_[z]});
        // What was commanded, recorded beside what the zone did (its manikin channels).
        out.model_channels.emplace_back(fmt::format("z{:02d}.skin_setpoint_c", map_.zones[z].zone), setpoint_c_[z]);
        out.model_channels.emplace_back(fmt::format("z{:02d}.sweat_setpoint_g_m2_h", map_.zones[z].zone), sweat_g_m2_h_[z]);
    }
}

void PhysiologicalLoop::fall_back(const std::string& why, LoopOutput& out) {
    phase_ = Phase::fallback;
    fallback_reason_ = why;
    out.fell_back = true;
    out.alarms.push_back({"error", fmt::format("physiological control fell back to constant skin temperature: {}; every "
                                               "zone holds its last setpoint and sweat rate (abort, or let the trial run "
                                               "out; it is flagged)",
                                               why)});
    for (std::size_t z = 0; z < map_.size(); ++z)
        out.commands.push_back({map_.zones[z].zone, setpoint_c_[z], sweat_g_m2_h_[z]});
    out.model_channels.emplace_back("fallback", 1.0);
}

void PhysiologicalLoop::record(const tr::StepState& st, const tr::SegmentValues& loss_w, const tr::Environment& env,
                               LoopOutput& out) {
    auto& c = out.model_channels;
    const auto nodes = body_.node_temps_c();
    const auto& names = tr::segment_names();
    const auto& areas = tr::Body::segment_areas_m2();
    double loss_total_w = 0.0, sweat_g_h = 0.0;
    c.emplace_back("time_s", body_.time_s());
    c.emplace_back("core_temp_c", st.sample.core_temp_c);
    c.emplace_back("mean_skin_temp_c", st.sample.mean_skin_temp_c);
    for (std::size_t i = 0; i < names.size(); ++i) {
        const std::string seg = names[i];
        c.emplace_back(seg + ".core_temp_c", nodes[4 * i]);
        c.emplace_back(seg + ".muscle_temp_c", nodes[4 * i + 1]);
        c.emplace_back(seg + ".fat_temp_c", nodes[4 * i + 2]);
        c.emplace_back(seg + ".skin_temp_c", nodes[4 * i + 3]);
        c.emplace_back(seg + ".heat_loss_w", loss_w[i]);
        c.emplace_back(seg + ".shell_storage_w", last_shell_w_[i]);  // taken out of the heaters' power
        c.emplace_back(seg + ".modelled_loss_w", st.modelled_loss_w[i]);
        c.emplace_back(seg + ".sweat_rate_g_m2_h", st.sweat_rate_g_m2_h[i]);
        c.emplace_back(seg + ".skin_blood_flow_l_h", st.skin_blood_flow_l_h[i]);
        loss_total_w += loss_w[i];
        sweat_g_h += st.sweat_rate_g_m2_h[i] * areas[i];
    }
    c.emplace_back("blood_temp_c", nodes[tr::node_count - 1]);
    c.emplace_back("heat_loss_w", loss_total_w);                   // measured, all segments, less the shell's storage
    // The shell's heat capacity the storage was taken with, and its standard uncertainty (Type B in `manikin physio`).
    c.emplace_back("shell_heat_capacity_j_m2k", cfg_.shell_heat_capacity_j_m2k);
    c.emplace_back("shell_heat_capacity_u_j_m2k", cfg_.shell_heat_capacity_u_j_m2k);
    c.emplace_back("metabolic_w", st.sample.metabolic_w);
    c.emplace_back("respiration_loss_w", -st.sample.respiration_w);
    c.emplace_back("storage_w", st.sample.storage_w);
    c.emplace_back("modelled_evaporation_w", -st.sample.evaporation_w);
    c.emplace_back("sweat_rate_g_h", sweat_g_h);
    // What the model was given besides the losses: `manikin physio` replays the run from these.
    c.emplace_back("air_temp_c", env.air_temp_c);
    c.emplace_back("air_rh_pct", env.rh_pct);
    c.emplace_back("mrt_c", env.mrt_c);
    c.emplace_back("air_speed_m_s", env.air_speed_m_s);
    c.emplace_back("metabolic_met", model_.metabolic_met);
    c.emplace_back("fallback", 0.0);
}

// Every zone's skin temperature now (NaN where its reading is not good).
std::vector<double> PhysiologicalLoop::skin_now(const LoopInputs& in) {
    std::vector<double> out(in.zones.size(), std::numeric_limits<double>::quiet_NaN());
    for (std::size_t z = 0; z < in.zones.size(); ++z)
        if (in.zones[z].good && std::isfinite(in.zones[z].skin_temp_c)) out[z] = in.zones[z].skin_temp_c;
    return out;
}

LoopOutput PhysiologicalLoop::tick(const LoopInputs& in) {
    LoopOutput out;
    if (phase_ == Phase::finished) return out;
    const std::int64_t now = in.now_ns;
    last_tick_ns_ = now;
    const std::size_t n = map_.size();
    if (in.zones.size() != n) throw std::invalid_argument("PhysiologicalLoop::tick: one reading per zone");
    const auto period_ns = static_cast<std::int64_t>(cfg_.coupling_period_s * 1e9);
    const std::vector<double>& initial_c = initial_skin_c_;

    // Time the campaign stood paused (the daemon's state says so, not the gap's length): the
    // model's clock stood still with the stage clock, so every reference time moves by it;
    // otherwise the model would catch up on the old losses and the setpoints step by the rate
    // times the pause. Any other gap between ticks (10 lab-seconds at --speed 10, a daemon that
    // stalled) is lab time that passed: the manikin kept losing heat, and the model integrates it.
    if (paused_seen_ns_ && in.paused_total_ns > *paused_seen_ns_) {
        const std::int64_t paused = in.paused_total_ns - *paused_seen_ns_;
        for (auto* t : {&started_ns_, &last_command_ns_, &running_since_ns_})
            if (*t) **t += paused;
        for (auto& t : off_since_ns_)
            if (t) *t += paused;
        on_target_since_ns_.reset();
    }
    paused_seen_ns_ = in.paused_total_ns;
    if (!started_ns_) {
        // The setpoints start where each zone is (never a jump) and move at the allowed rate.
        started_ns_ = now;
        for (std::size_t z = 0; z < n; ++z)
            setpoint_c_[z] = in.zones[z].good && std::isfinite(in.zones[z].skin_temp_c) ? in.zones[z].skin_temp_c : initial_c[z];
        last_command_ns_ = now;
        command_towards(initial_c, std::vector<double>(n, 0.0), 0.0, out);
        out.alarms.push_back({"info", fmt::format("physiological trial: preconditioning the zones to the model's initial "
                                                  "skin temperatures ({:.2f}-{:.2f} °C) at up to {} °C/min",
                                                  *std::min_element(initial_c.begin(), initial_c.end()),
                                                  *std::max_element(initial_c.begin(), initial_c.end()),
                                                  cfg_.max_setpoint_rate_c_min)});
        return out;
    }
    // The measured losses: every good flux reading since the last model step, averaged per zone.
    for (std::size_t z = 0; z < n; ++z) {
        const auto& r = in.zones[z];
        if (r.good && r.flux_mono_ns > last_flux_ns_[z] && std::isfinite(r.heat_flux_w_m2)) {
            flux_sum_w_m2_[z] += r.heat_flux_w_m2;
            ++flux_count_[z];
            last_flux_ns_[z] = r.flux_mono_ns;
        }
    }
    if (phase_ == Phase::fallback) {
        const std::int64_t t0 = running_since_ns_.value_or(*started_ns_);
        if (static_cast<double>(now - t0) * 1e-9 >= model_.duration_s) {
            phase_ = Phase::finished;
            out.finished = true;
        }
        return out;
    }
    // A zone that cannot follow its setpoint (a failed heater, a zone the coolant cannot hold).
    for (std::size_t z = 0; z < n; ++z) {
        const auto& r = in.zones[z];
        if (!r.good || !std::isfinite(r.skin_temp_c)) continue;
        if (std::abs(r.skin_temp_c - setpoint_c_[z]) <= cfg_.follow_tolerance_c) {
            off_since_ns_[z].reset();
        } else if (!off_since_ns_[z]) {
            off_since_ns_[z] = now;
        } else if (static_cast<double>(now - *off_since_ns_[z]) * 1e-9 > cfg_.follow_timeout_s) {
            fall_back(fmt::format("zone {} ({}) cannot follow its setpoint: {:.2f} °C for {:.2f} °C, off by more than "
                                  "{} °C for over {:.0f} min",
                                  map_.zones[z].zone, map_.zones[z].name, r.skin_temp_c, setpoint_c_[z],
                                  cfg_.follow_tolerance_c, cfg_.follow_timeout_s / 60),
                      out);
            return out;
        }
    }
    if (now - *last_command_ns_ < period_ns) return out;
    const double dt_s = static_cast<double>(now - *last_command_ns_) * 1e-9;
    last_command_ns_ = now;

    if (phase_ == Phase::preconditioning) {
        command_towards(initial_c, std::vector<double>(n, 0.0), dt_s, out);
        bool on_target = true;
        for (std::size_t z = 0; z < n; ++z)
            on_target = on_target && std::abs(setpoint_c_[z] - initial_c[z]) < 1e-9 && in.zones[z].good &&
                        std::abs(in.zones[z].skin_temp_c - initial_c[z]) <= precondition_band_c;
        if (!on_target) on_target_since_ns_.reset();
        else if (!on_target_since_ns_) on_target_since_ns_ = now;
        if (on_target_since_ns_ && static_cast<double>(now - *on_target_since_ns_) * 1e-9 >= precondition_hold_s) {
            phase_ = Phase::running;
            running_since_ns_ = now;
            skin_at_step_c_ = skin_now(in);
            std::fill(flux_sum_w_m2_.begin(), flux_sum_w_m2_.end(), 0.0);
            std::fill(flux_count_.begin(), flux_count_.end(), 0);
            out.alarms.push_back({"info", fmt::format("physiological trial: the model starts ({}, {} met, {:.0f} min, "
                                                      "coupled every {} s)",
                                                      model_.name, model_.metabolic_met, model_.duration_s / 60,
                                                      cfg_.coupling_period_s)});
        } else if (const double limit_s = cfg_.follow_timeout_s + precondition_limit_extra_s;
                   static_cast<double>(now - *started_ns_) * 1e-9 > limit_s) {
            fall_back(fmt::format("the zones did not reach the model's initial skin temperatures within {:.0f} min "
                                  "(physiological.follow_timeout_s + {:.0f} min of preconditioning)",
                                  limit_s / 60, precondition_limit_extra_s / 60),
                      out);
        }
        return out;
    }

    // ---- Running: one coupling step ----
    for (std::size_t z = 0; z < n; ++z)
        if (last_flux_ns_[z] < 0 || static_cast<double>(now - last_flux_ns_[z]) * 1e-9 > cfg_.stale_after_s) {
            fall_back(fmt::format("zone {} ({}): its heat flux is {} ({}; physiological.stale_after_s = {} s)",
                                  map_.zones[z].zone, map_.zones[z].name,
                                  in.zones[z].flagged ? "flagged by the manikin (a heater or sensor fault)" : "stale",
                                  last_flux_ns_[z] < 0 ? std::string("never read")
                                                       : fmt::format("last good reading {:.0f} s ago",
                                                                     static_cast<double>(now - last_flux_ns_[z]) * 1e-9),
                                  cfg_.stale_after_s),
                      out);
            return out;
        }
    if (!std::isfinite(in.air_temp_c) || !std::isfinite(in.rh_pct) || !std::isfinite(in.wall_temp_c)) {
        fall_back("the enclosure's air temperature, humidity or wall temperature is not being read", out);
        return out;
    }
    // Segment loss: the area-weighted mean flux of its zones over the model segment's own area,
    // less what warmed the shell: the heaters' power is the surface's loss plus C dT_skin/dt.
    tr::SegmentValues flux_area{}, shell_area{}, loss_w{};
    const std::vector<double> skin_c = skin_now(in);
    double measured_w = 0.0, shell_w = 0.0;
    for (std::size_t z = 0; z < n; ++z) {
        const double mean_w_m2 = flux_count_[z] > 0 ? flux_sum_w_m2_[z] / flux_count_[z] : in.zones[z].heat_flux_w_m2;
        double storage_w_m2 = 0.0;
        if (z < skin_at_step_c_.size() && std::isfinite(skin_at_step_c_[z]) && std::isfinite(skin_c[z]) && dt_s > 0.0)
            storage_w_m2 = cfg_.shell_heat_capacity_j_m2k * (skin_c[z] - skin_at_step_c_[z]) / dt_s;
        flux_area[static_cast<std::size_t>(zone_segment_[z])] += (mean_w_m2 - storage_w_m2) * map_.zones[z].area_m2;
        shell_area[static_cast<std::size_t>(zone_segment_[z])] += storage_w_m2 * map_.zones[z].area_m2;
        measured_w += mean_w_m2 * map_.zones[z].area_m2;
        shell_w += storage_w_m2 * map_.zones[z].area_m2;
        flux_sum_w_m2_[z] = 0.0;
        flux_count_[z] = 0;
    }
    skin_at_step_c_ = skin_c;
    const auto& areas = tr::Body::segment_areas_m2();
    for (std::size_t m = 0; m < loss_w.size(); ++m) {
        loss_w[m] = flux_area[m] / segment_zone_area_m2_[m] * areas[m];
        last_shell_w_[m] = shell_area[m] / segment_zone_area_m2_[m] * areas[m];  // as the loss, on the model's areas
    }
    last_loss_w_ = loss_w;
    // The record keeps both: what the heaters gave and what went into the shell (the zones' own area).
    out.model_channels.emplace_back("heater_power_w", measured_w);
    out.model_channels.emplace_back("shell_storage_w", shell_w);
    const tr::Environment env{in.air_temp_c, in.wall_temp_c, in.rh_pct, std::max(0.0, in.air_speed_m_s)};
    const double model_target_s = std::min(static_cast<double>(now - *running_since_ns_) * 1e-9, model_.duration_s);
    const tr::StepState* st = nullptr;
    try {
        while (body_.time_s() + 1.0 <= model_target_s + 1e-9) st = &body_.step(1.0, env, &loss_w);
    } catch (const std::exception& e) {
        fall_back(fmt::format("the model diverged: {}", e.what()), out);
        return out;
    }
    if (!st) return out;
    const double core_c = st->sample.core_temp_c;
    if (!std::isfinite(core_c) || core_c < cfg_.min_core_temp_c || core_c > cfg_.max_core_temp_c) {
        fall_back(fmt::format("the model diverged: core {:.2f} °C is outside physiological.min/max_core_temp_c = {}..{} °C",
                              core_c, cfg_.min_core_temp_c, cfg_.max_core_temp_c),
                  out);
        return out;
    }
    std::vector<double> target_c(n), sweat(n);
    for (std::size_t z = 0; z < n; ++z) {
        const auto m = static_cast<std::size_t>(zone_segment_[z]);
        target_c[z] = st->skin_temp_c[m];
        sweat[z] = st->sweat_rate_g_m2_h[m];
    }
    command_towards(target_c, sweat, dt_s, out);
    record(*st, loss_w, env, out);
    while (next_phase_ < model_.phases.size() && body_.time_s() >= model_.phases[next_phase_].after_s) {
        out.chamber_change = model_.phases[next_phase_];
        out.alarms.push_back({"info", fmt::format("physiological trial: the protocol's next phase at {:.0f} min: chamber {} °C, "
                                                  "{} % RH",
                                                  model_.phases[next_phase_].after_s / 60,
                                                  model_.phases[next_phase_].chamber_temp_c,
                                                  model_.phases[next_phase_].chamber_rh_pct)});
        ++next_phase_;
    }
    if (body_.time_s() >= model_.duration_s - 1e-9) {
        phase_ = Phase::finished;
        out.finished = true;
    }
    return out;
}

nlohmann::json PhysiologicalLoop::status_json() const {
    static const char* const phase_names[] = {"preconditioning", "running", "fallback", "finished"};
    nlohmann::json j = {{"model", model_.name},
                        {"phase", phase_names[static_cast<int>(phase_)]},
                        {"model_time_s", body_.time_s()},
                        {"duration_s", model_.duration_s}};
    const auto nodes = body_.node_temps_c();
    j["core_temp_c"] = nodes[4];  // trunk core, as the model reports "core"
    double skin = 0.0, area = 0.0;
    const auto& areas = tr::Body::segment_areas_m2();
    nlohmann::json segments = nlohmann::json::object();
    for (std::size_t i = 0; i < tr::segment_count; ++i) {
        skin += nodes[4 * i + 3] * areas[i];
        area += areas[i];
        segments[tr::segment_names()[i]] = {{"skin_temp_c", nodes[4 * i + 3]},
                                            {"core_temp_c", nodes[4 * i]},
                                            {"heat_loss_w", running_since_ns_ ? nlohmann::json(last_loss_w_[i]) : nlohmann::json()}};
    }
    j["mean_skin_temp_c"] = skin / area;
    // How long the phase has run and, preconditioning, when it gives up (issue 64: shown nowhere).
    if (last_tick_ns_ && started_ns_) {
        const double since_start_s = static_cast<double>(*last_tick_ns_ - *started_ns_) * 1e-9;
        if (phase_ == Phase::preconditioning) {
            j["phase_elapsed_s"] = since_start_s;
            j["phase_limit_s"] = cfg_.follow_timeout_s + precondition_limit_extra_s;
            j["on_start_s"] = on_target_since_ns_ ? static_cast<double>(*last_tick_ns_ - *on_target_since_ns_) * 1e-9 : 0.0;
            j["hold_s"] = precondition_hold_s;  // every zone within precondition_band_c this long starts the model
        } else if (running_since_ns_) {
            j["phase_elapsed_s"] = static_cast<double>(*last_tick_ns_ - *running_since_ns_) * 1e-9;
        }
    }
    j["segments"] = segments;
    if (!fallback_reason_.empty()) j["fallback_reason"] = fallback_reason_;
    return j;
}

}  // namespace manikind
