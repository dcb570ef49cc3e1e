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

#include "physics/thermoreg/stepwise_math.hpp"

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

// One step's surroundings (what Exposure holds for a whole run).
struct Environment {
    double air_temp_c = 41.0;
    double mrt_c = 55.0;
    double rh_pct = 20.0;
    double air_speed_m_s = 0.0;
};
using SegmentValues = std::array<double, segment_count>;

// Latent heat of the sweat a segment's evaporation stands for (ISO 9886: 2430 J/g near 30 °C).
inline constexpr double sweat_latent_heat_j_g = 2430.0;

// What one step leaves, per segment as well as Fig. 4's whole-body quantities.
struct StepState {
    OutputSample sample;                  // t_s: the step's start; temperatures after it
    SegmentValues skin_temp_c{};          // after the step
    SegmentValues core_temp_c{};
    SegmentValues skin_loss_w{};          // what the skin lost to the surroundings: measured when given, else modelled
    SegmentValues modelled_loss_w{};      // the model's own sensible + evaporative loss, for comparison
    SegmentValues evaporation_w{};        // the model's skin evaporation (diffusion + regulatory sweat)
    SegmentValues sweat_rate_g_m2_h{};    // the same as a moisture supply per m² of the segment
    SegmentValues skin_blood_flow_l_h{};
};

// The model stepped one time step at a time: what simulate() runs for a whole exposure, and what
// a manikin in the loop runs fed the manikin's measured losses. State: the 25 node temperatures.
class Body {
public:
    // At the JOS-3 set points; met is the metabolic rate (0.7-10). Throws std::domain_error.
    Body(double met, const ModelOptions& options);
    // One explicit step of dt_s (<= 5 s). With measured_skin_loss_w (W per segment, positive =
    // lost: sensible + evaporative, as a manikin's heaters supply it), the skin nodes lose that
    // instead of the model's own exchange; respiration and the sweat request stay the model's.
    // Throws std::domain_error for inputs out of range or a step that goes unstable.
    const StepState& step(double dt_s, const Environment& env, const SegmentValues* measured_skin_loss_w = nullptr);
    double time_s() const { return time_s_; }
    // Node temperatures, °C, in the code's order (per segment core, muscle, fat, skin; then blood).
    std::array<double, node_count> node_temps_c() const;
    // Continue from a recorded state (a restarted daemon); throws std::domain_error for a
    // temperature outside 20-45 °C or not finite.
    void restore(double time_s, const std::array<double, node_count>& node_temps_c);
    double max_abs_energy_residual_w() const { return max_abs_residual_w_; }
    static const SegmentValues& segment_areas_m2();

private:
    void prepare(double dt_s, const Environment& env);  // per-environment constants, when it changes
    ModelOptions options_;
    double met_;
    double time_s_ = 0.0;
    std::array<double, node_count> t_k_{};
    double max_abs_residual_w_ = 0.0;
    StepState state_;
    // Per segment: ln T_skin, the saturation pressure's exponentials and the local vasomotor
    // factor, each updated from its previous step's value (stepwise_math.hpp).
    std::array<SteppedLog, segment_count> ln_skin_k_;
    std::array<SteppedExp, segment_count> psat_growth_exp_, psat_scale_exp_, local_factor_exp_;
    // What depends only on the environment and the step, computed when either changes.
    bool prepared_ = false;
    Environment env_;
    double dt_s_ = 0.0;
    double air_k_ = 0.0, mrt_k_ = 0.0, p_air_pa_ = 0.0, c_air_ = 0.0, q_total_w_ = 0.0, q_work_w_ = 0.0;
    double per_step_1_s_ = 0.0;
    SegmentValues h_forced_w_m2k_{}, clothing_r_m2k_w_{}, clothing_re_m2pa_w_{};
    std::array<double, node_count> step_per_capacity_s_k_j_{};
};

// Throws std::domain_error naming the input for non-physical or unstable inputs: RH outside
// 0-100 %, negative air speed or period, duration or step not positive, a step too long for
// the explicit scheme (the fastest nodes' time constant is ~6 s at full skin blood flow, so
// steps above 5 s are refused), output interval not a multiple of the step.
void validate(const Exposure& exposure);

SimulationResult simulate(const Exposure& exposure, const ModelOptions& options);

}  // namespace manikind::physics::thermoreg
