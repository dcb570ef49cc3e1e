#pragma once
// The simulated world the virtual devices measure: a climatic chamber following its setpoints,
// the sealed enclosure inside it (air, walls, humidity) lagging behind, and the manikin's zones
// under the manikin's own PI skin-temperature control, losing heat by the physics in
// `physics/twin` with a configurable list of terms (including ones the twin under test lacks).
// Sensors add noise; faults (a failed heater, a stuck sensor) are set here. Pure state and
// arithmetic: time advances only through step(), so the same world runs on a virtual clock
// in tests or paced by the real clock.
#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "physics/twin/twin.hpp"
#include "protocol/manikin_can.hpp"
#include "sim/campaign/campaign_generator.hpp"

namespace manikind::sim {

struct WorldOptions {
    std::vector<ZoneSpec> zones;                 // the manikin's zone map
    physics::twin::TwinVersion physics;          // the world's physics (baseline + hidden terms)
    double initial_temp_c = 22.0;
    double initial_rh_pct = 40.0;
    double chamber_time_constant_s = 300.0;      // chamber air after a setpoint change
    double enclosure_time_constant_s = 600.0;    // sealed enclosure behind the chamber
    double wall_time_constant_s = 1200.0;
    double wall_below_air_c = 0.4;               // walls a little cooler than the air (Text S3.3)
    double air_speed_m_s = 0.01;                 // sealed enclosure: < 0.02 m/s (Text S3.1)
    // A non-uniform room ([[simulation.local]]): per zone [zone - 1], what that zone meets beside
    // what the probes read (a warm windscreen, a vent jet, a heated seat, the sun); empty: uniform.
    // The devices never report it: the probes read the room's air and walls as before.
    std::vector<physics::twin::LocalEnvironment> local;
    double shell_heat_capacity_j_m2k = 2500.0;   // zone shell; ~5 min time constant
    double pi_kp_w_m2k = 120.0;                  // the manikin's own skin-temperature loop
    double pi_ki_w_m2ks = 0.8;
    double max_heater_power_w_m2 = 600.0;
    double watchdog_s = 5.0;                     // no host heartbeat for this long: heaters off
    // Sensor noise (1 sigma).
    double skin_noise_c = 0.004, flux_noise_w_m2 = 1.5, air_noise_c = 0.03, rh_noise_pct = 0.3;
    double wall_noise_c = 0.05, speed_noise_m_s = 0.003;
    std::uint64_t seed = 1;
    // Replicate scatter, drawn per trial (see World::trial_scatter) from its own seeded stream.
    ReplicateScatter scatter;
    // The enclosure's own offsets from the chamber for given chamber setpoints (the paper's
    // measured T_air, RH_air of Table S3 for its T_c, RH_c); nearest match within 0.5 °C / 1 %.
    std::vector<CampaignCase> enclosure_table;
};

struct ZoneState {
    double skin_temp_c = 22.0;
    double heater_power_w_m2 = 0.0;
    double integral_w_m2 = 0.0;
    double loss_w_m2 = 0.0;                      // heat lost to the enclosure (physics)
    protocol::manikin_can::ControlMode mode = protocol::manikin_can::ControlMode::constant_skin_temp;
    double setpoint = 35.0;                      // °C or W/m² by mode
    bool sweating = false;
    double sweat_rate_g_m2_h = 0.0;
    // Set by a command addressed to this zone alone (a physiological model's per-zone rates): the
    // supply is metered and evaporates up to what the air takes (w = supply / E_max, at most 1).
    // An all-zones command floods the textile skin (w = 1), as in the paper's wet trials.
    bool metered = false;
    double wettedness = 0.0;                     // this step's, as the physics used it
    bool heater_failed = false;
};

// One trial's draw of the replicate scatter. A trial runs from one manikin start to its stop;
// the next trial's draw is taken when the manikin stops, so the enclosure has settled to it
// before the next trial starts (the first is drawn at construction).
struct TrialScatter {
    int trial = 1;                               // 1 for the first trial, +1 at every manikin stop
    double air_error_c = 0.0;                    // actual enclosure air minus its nominal offset from the chamber
    double rh_error_pct = 0.0;
    double wall_error_c = 0.0;                   // actual walls off their usual offset below the air
    std::vector<double> probe_air_error_c;       // [probe - 1] recorded minus actual
    std::vector<double> probe_rh_error_pct;      // [probe - 1]
    std::vector<double> probe_wall_error_c;      // [thermocouple - 1]
    std::vector<double> zone_flux_factor;        // [zone - 1] 1 + e applied to the physics' loss
    std::vector<double> zone_flux_offset_w_m2;   // [zone - 1]
};

class World {
public:
    explicit World(WorldOptions options);

    void step(double dt_s);
    double time_s() const { return time_s_; }

    // Chamber controller.
    void set_chamber_setpoints(double temp_c, double rh_pct);
    double chamber_temp_setpoint_c() const { return chamber_sp_c_; }
    double chamber_rh_setpoint_pct() const { return chamber_sp_rh_; }
    double chamber_air_temp_c() const { return chamber_air_c_; }   // the controller's own sensor
    double chamber_rh_pct() const { return chamber_rh_; }

    // Enclosure truth and sensor readings (with noise).
    double enclosure_air_temp_c() const { return air_c_; }
    double enclosure_rh_pct() const { return rh_; }
    double wall_temp_c() const { return wall_c_; }
    double measure_air_temp_c(int probe);
    double measure_rh_pct(int probe);
    double measure_wall_temp_c(int thermocouple);
    double measure_air_speed_m_s();

    // Manikin.
    void manikin_command(const protocol::manikin_can::Setpoint& sp);
    void manikin_control(bool run);              // a host Control frame (also the heartbeat)
    // The operator dresses the manikin (clothing tests): `clothing` twin terms over the world's
    // physics from now on; empty = nude.
    void wear(std::vector<physics::twin::Term> clothing);
    // The room a campaign's case states ([[cases.local]], one entry per zone); empty: the room the
    // world was made with ([[simulation.local]], or uniform). Returns false for a wrong size.
    bool set_room(const std::vector<physics::twin::LocalEnvironment>& room);
    bool manikin_running() const { return run_; }
    bool watchdog_tripped() const { return watchdog_tripped_; }
    int zone_count() const { return static_cast<int>(zones_.size()); }
    const ZoneState& zone(int zone) const { return zones_.at(static_cast<std::size_t>(zone - 1)); }
    protocol::manikin_can::ZoneStatus measure_zone(int zone);
    void fail_heater(int zone, bool failed);

    // This trial's scatter (ground truth for tests; the devices never report it).
    const TrialScatter& trial_scatter() const { return scatter_; }
    static constexpr int max_probes = 8;         // per-probe errors drawn for probes 1..8; more reuse the last

private:
    void apply_enclosure_offsets();
    void draw_trial_scatter();
    static std::size_t probe_index(int probe);
    double gauss(double sd) { return sd > 0.0 ? sd * normal_(rng_) : 0.0; }

    WorldOptions o_;
    double time_s_ = 0.0;
    double chamber_sp_c_, chamber_sp_rh_, chamber_air_c_, chamber_rh_;
    double air_c_, rh_, wall_c_;
    double air_offset_c_ = 0.0, rh_offset_pct_ = 0.0;
    std::vector<ZoneState> zones_;
    physics::twin::TrialConditions conditions_;
    bool run_ = false;
    bool watchdog_tripped_ = false;
    double last_heartbeat_s_ = 0.0;
    std::mt19937_64 rng_;
    std::normal_distribution<double> normal_{0.0, 1.0};
    // Scatter has its own stream: how many readings the devices took (which varies with
    // polling in real time) never changes a trial's draw, only the seed and trial number do.
    std::mt19937_64 scatter_rng_;
    TrialScatter scatter_;
    std::vector<physics::twin::Term> clothing_;  // worn now (wear())
    physics::twin::TwinVersion dressed_;         // o_.physics + clothing_
};

}  // namespace manikind::sim
