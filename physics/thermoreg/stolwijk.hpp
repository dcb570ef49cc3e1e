#pragma once
// The paper's thermoregulation model (Supplementary "Matlab thermoregulation code", the
// Stolwijk-1971 model as updated by Joshi et al. 2025 and Viswanathan et al. 2026): six
// segments (head, trunk, arms, hands, legs, feet) x four nodes (core, muscle, fat, skin) and a
// central blood pool, 25 nodes, explicit time stepping; JOS-3 set points and control signals,
// skin blood flow, sweating, shivering, clothing, respiration. The free-convection law is
// pluggable (Table 2), mixed with forced convection by Eq. 9.
//
// `seed_compatible` reproduces the published code exactly, including what differs from the
// physics the paper describes; the default corrects those (docs/thermoregulation.md lists each
// difference and its effect on Fig. 4). Pure: no I/O.
#include <array>
#include <string>
#include <vector>

namespace manikind::physics::thermoreg {

inline constexpr int segment_count = 6;   // head, trunk, arms, hands, legs, feet
inline constexpr int node_count = 25;     // 6 x (core, muscle, fat, skin) + central blood
const std::array<const char*, segment_count>& segment_names();

enum class ConvectionModel {
    coupled,             // h0 + B(sign of mean N) |dT + 146 dC|^(1/4) (Eq. 8 form, Table 2 / the code)
    dt_only,             // Wissler A |dT|^(1/4) (Table 2)
    constant_stolwijk,   // Table 2, Stolwijk
    constant_jos,        // Table 2, JOS-2/3
};
const char* to_string(ConvectionModel m);

// Air speed over time: constant, or a square wave between 0 and speed_m_s (Fig. S23B).
struct AirSpeedSchedule {
    double speed_m_s = 0.0;
    double square_wave_period_s = 0.0;  // 0: constant; else on for the first half of each period
    double at(double t_s) const;
};

struct Exposure {
    double air_temp_c = 41.0;    // Fig. 4: 41 °C
    double mrt_c = 55.0;         // Fig. 4: mean radiant temperature 55 °C
    double rh_pct = 20.0;        // Fig. 4: 20 %
    double met = 1.5;            // Fig. 4: 1.5 met
    AirSpeedSchedule air_speed;  // Fig. 4: still air
    double duration_s = 7200.0;  // Fig. 4: 2 h
    double time_step_s = 1.0;    // the code's dTime
    double output_interval_s = 60.0;
};

// The code's clothing: 0.054 m²K/W (and 9.4 m²Pa/W) on trunk, legs and feet, 0.26 clo
// area-weighted over the body.
inline constexpr double default_clo = 0.26;

struct ModelOptions {
    ConvectionModel convection = ConvectionModel::coupled;
    bool seed_compatible = false;
    // Whole-body (area-weighted) intrinsic clothing insulation in clo: the code's layout scaled,
    // dry and evaporative alike, by clo / default_clo; 0 = bare (the manikin undressed).
    double clo = default_clo;
};

// Fig. 4's quantities; heat rates in W with Fig. 4's sign: positive = heat gained by the body.
struct OutputSample {
    double t_s = 0.0;
    double core_temp_c = 0.0;         // trunk core (node 5), as the code's "Core temperature"
    double mean_skin_temp_c = 0.0;    // area-weighted
    double convection_w = 0.0;
    double radiation_w = 0.0;
    double evaporation_w = 0.0;       // skin evaporation (negative: cooling)
    double respiration_w = 0.0;       // respiratory exchange (negative: loss)
    double metabolic_w = 0.0;         // heat generated in the body
    double storage_w = 0.0;           // the rate of change of body heat content
    double mean_buoyancy_drive_c = 0.0;  // mean over segments of dT + 146 dC (Fig. 4B/D, unscaled)
    double mean_skin_wettedness = 0.0;
    double energy_residual_w = 0.0;   // storage - (production - losses): zero up to rounding
};

struct SimulationResult {
    std::vector<OutputSample> series;     // every output_interval_s, starting at t = 0
    OutputSample final;
    double max_abs_energy_residual_w = 0.0;
    std::array<double, node_count> final_node_temps_c{};
};

// Throws std::domain_error naming the input for non-physical or unstable inputs: RH outside
// 0-100 %, negative air speed or period, duration or step not positive, a step too long for
// the explicit scheme (the fastest nodes' time constant is ~6 s at full skin blood flow, so
// steps above 5 s are refused), output interval not a multiple of the step.
void validate(const Exposure& exposure);

SimulationResult simulate(const Exposure& exposure, const ModelOptions& options);

}  // namespace manikind::physics::thermoreg
