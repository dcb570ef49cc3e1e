#include "physics/thermoreg/stolwijk.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "physics/range_check.hpp"
#include "physics/thermoreg/stepwise_math.hpp"

namespace manikind::physics::thermoreg {
namespace {

using Segments = std::array<double, segment_count>;
using Nodes = std::array<double, node_count>;

// ---- The code's tables (node order: per segment core, muscle, fat, skin; then central blood) ----
constexpr Nodes heat_capacity_j_k = {9288.48, 1380.72, 920.48,  1004.16, 41086.88, 67571.6, 17782.0, 5062.64, 5899.44,
                                     12719.36, 2426.72, 1799.12, 585.76,  251.04,   376.56,  711.28,  17740.16, 38367.28,
                                     5983.12, 4518.72, 962.32,  251.04,  543.92,   920.48,  9414.00};
constexpr Nodes basal_metabolism_w = {14.93, 0.12, 0.13, 0.09, 52.78, 5.82, 2.48, 0.47, 0.81, 1.10, 0.20, 0.15, 0.09,
                                      0.23,  0.03, 0.06, 2.59,  3.33, 0.50, 0.37, 0.15, 0.02, 0.05, 0.08, 0.00};
constexpr Nodes basal_blood_flow_l_h = {45.00, 0.12, 0.13, 1.44, 210.00, 6.00, 2.56, 2.10, 0.84, 1.14, 0.20, 0.50, 0.10,
                                        0.24,  0.04, 2.00, 2.69,  3.43, 0.52, 2.85, 0.16, 0.02, 0.05, 3.00, 0.00};
constexpr Nodes conductance_w_k = {1.605,  13.258, 16.049, 0.0, 1.593,  5.524,  23.027, 0.0, 1.396,
                                   10.351, 30.471, 0.0,    6.397, 11.223, 11.514, 0.0,    10.467, 14.421,
                                   74.432, 0.0,    16.282, 20.585, 16.398, 0.0,   0.0};
// JOS-3 set points, kelvin (the code keeps node temperatures in kelvin).
constexpr Nodes set_point_k = {310.61, 308.69, 308.58, 308.35, 310.18, 309.57, 308.87, 307.93, 309.29,
                               307.86, 307.69, 307.34, 308.20, 308.17, 307.67, 307.59, 309.81, 309.29,
                               308.46, 307.25, 307.89, 307.78, 307.46, 307.39, 310.49};

constexpr Segments area_m2 = {0.133, 0.680, 0.254, 0.095, 0.597, 0.130};
constexpr Segments df_work = {0.000, 0.300, 0.080, 0.010, 0.600, 0.010};
constexpr Segments df_receptors = {0.0695, 0.4935, 0.0686, 0.1845, 0.1505, 0.0334};
constexpr Segments df_vasodilation = {0.1320, 0.3220, 0.0950, 0.1210, 0.2300, 0.1000};
constexpr Segments df_vasoconstriction = {0.0500, 0.1500, 0.0500, 0.3500, 0.0500, 0.3500};
constexpr Segments df_sweat = {0.0810, 0.4810, 0.1540, 0.0310, 0.2180, 0.0350};
constexpr Segments df_shiver = {0.0200, 0.8500, 0.0500, 0.0000, 0.0700, 0.0000};
// Clothing: 0.26 clo concentrated on trunk, legs and feet (the code's Rc_cl, Re_cl).
constexpr Segments clothing_layout_r_m2k_w = {0.0, 0.054, 0.0, 0.0, 0.054, 0.054};
constexpr Segments clothing_layout_re_m2pa_w = {0.0, 9.4, 0.0, 0.0, 9.4, 9.4};
// Heat transfer coefficients: forced (de Dear, a v^b), radiation, Table 2 free convection.
constexpr Segments forced_a = {3.20, 8.1, 11.09, 14.40, 11.10, 12.00};
constexpr Segments forced_b = {0.97, 0.62, 0.59, 0.55, 0.51, 0.49};
constexpr Segments radiation_w_m2k = {4.89, 4.26, 4.49, 4.21, 5.08, 6.14};
constexpr Segments coupled_h0 = {0.567, 0.29, 0.937, 0.5, 0.575, 1.151};
constexpr Segments coupled_b_pos = {1.036, 0.996, 1.278, 2.4, 1.233, 1.673};  // the code's hc_e
constexpr Segments coupled_b_neg = {1.4, 1.03, 1.164, 2.4, 0.623, 0.831};     // the code's hc_g
constexpr Segments wissler_a = {2.6, 1.5, 1.9, 2.7, 2.15, 1.57};
constexpr Segments stolwijk_h = {0.660, 1.860, 3.950, 6.050, 3.610, 5.930};
constexpr Segments jos_h = {4.480, 2.910, 3.590, 3.670, 2.530, 2.040};

constexpr double lewis_k_per_pa = 16.5 / 1000.0;  // Eq. S5, per Pa
constexpr double basal_total_w = 86.45;
constexpr double blood_heat_w_h_per_l_k = 1.163;  // W per (l/h) per K
constexpr int core_trunk = 4;                     // node 5 in the code
constexpr int central_blood = 24;

int skin(int segment) { return 4 * segment + 3; }

// The seed formula exp(77.3450 + 0.0057 T - 7235/T) / T^8.2 with the power folded into the
// exponent: one exp and one log per call (this runs ~10^5 times per simulated hour).
double psat_exponent(double t_k, double ln_t_k) { return 77.3450 + 0.0057 * t_k - 7235.0 / t_k - 8.2 * ln_t_k; }
double psat_pa(double t_k) { return std::exp(psat_exponent(t_k, std::log(t_k))); }
double quarter_power(double x) { return std::sqrt(std::sqrt(std::abs(x))); }

// A sum in four interleaved partial sums: one running sum is a chain of dependent additions
// (25 x 4 cycles per reduction), three of which ran every step.
double sum_of(const double* v, int n) {
    double a = 0.0, b = 0.0, c = 0.0, d = 0.0;
    int i = 0;
    for (; i + 4 <= n; i += 4) a += v[i], b += v[i + 1], c += v[i + 2], d += v[i + 3];
    for (; i < n; ++i) a += v[i];
    return (a + b) + (c + d);
}

}  // namespace

const std::array<const char*, segment_count>& segment_names() {
    static const std::array<const char*, segment_count> names = {"head", "trunk", "arms", "hands", "legs", "feet"};
    return names;
}

const char* to_string(ConvectionModel m) {
    switch (m) {
        case ConvectionModel::coupled: return "coupled";
        case ConvectionModel::dt_only: return "dt-only";
        case ConvectionModel::constant_stolwijk: return "constant-stolwijk";
        case ConvectionModel::constant_jos: return "constant-jos";
    }
    return "?";
}

double AirSpeedSchedule::at(double t_s) const {
    if (square_wave_period_s <= 0.0) return speed_m_s;
    const double phase = std::fmod(t_s, square_wave_period_s);
    return phase < 0.5 * square_wave_period_s ? speed_m_s : 0.0;
}

void validate(const Exposure& e) {
    require_in_range("relative humidity", e.rh_pct, 0.0, 100.0, "%");
    require_in_range("air temperature", e.air_temp_c, -40.0, 70.0, "degC");
    require_in_range("mean radiant temperature", e.mrt_c, -40.0, 150.0, "degC");
    require_in_range("metabolic rate", e.met, 0.7, 10.0, "met");
    require_in_range("air speed", e.air_speed.speed_m_s, 0.0, 20.0, "m/s");
    require_in_range("square-wave period", e.air_speed.square_wave_period_s, 0.0, 86400.0, "s");
    require_in_range("duration", e.duration_s, 1.0, 7.0 * 86400.0, "s");
    // The fastest nodes (skin at full blood flow, 90 l/h) have time constants near 6 s; the
    // explicit scheme needs a step below that to stay stable.
    require_in_range("time step", e.time_step_s, 1e-3, 5.0, "s");
    require_in_range("output interval", e.output_interval_s, e.time_step_s, e.duration_s, "s");
    const double ratio = e.output_interval_s / e.time_step_s;
    if (std::abs(ratio - std::round(ratio)) > 1e-9)
        throw std::domain_error("output interval must be a whole number of time steps");
}

namespace {
// Vapour concentration C = p M_w / (R T). The code uses M_w = 18 g/mol and adds 273.15 to a
// temperature already in kelvin, which roughly halves C (docs/thermoregulation.md, D1).
double concentration(bool seed, double p_pa, double t_k) {
    return seed ? p_pa * 18e-3 / ((t_k + 273.15) * 8.314) : p_pa * 18.02e-3 / (t_k * 8.314);
}
}  // namespace

const SegmentValues& Body::segment_areas_m2() { return area_m2; }

Body::Body(double met, const ModelOptions& opt) : options_(opt), met_(met) {
    require_in_range("metabolic rate", met, 0.7, 10.0, "met");
    if (!(opt.clo >= 0.0 && opt.clo <= 4.0)) throw std::domain_error("clo must be within 0..4");
    // The clothing layout scaled to the requested whole-body insulation (default: the code's).
    for (std::size_t i = 0; i < clothing_r_m2k_w_.size(); ++i) {
        clothing_r_m2k_w_[i] = clothing_layout_r_m2k_w[i] * (opt.clo / default_clo);
        clothing_re_m2pa_w_[i] = clothing_layout_re_m2pa_w[i] * (opt.clo / default_clo);
    }
    t_k_ = set_point_k;
}

std::array<double, node_count> Body::node_temps_c() const {
    std::array<double, node_count> c{};
    for (int j = 0; j < node_count; ++j) c[j] = t_k_[j] - 273.15;
    return c;
}

void Body::restore(double time_s, const std::array<double, node_count>& node_temps_c) {
    for (int j = 0; j < node_count; ++j)
        if (!(node_temps_c[j] >= 20.0 && node_temps_c[j] <= 45.0))
            throw std::domain_error("a restored node temperature must be within 20-45 °C");
    for (int j = 0; j < node_count; ++j) t_k_[j] = node_temps_c[j] + 273.15;
    time_s_ = time_s;
    // The exp/log trackers start exact again from the restored temperatures.
    ln_skin_k_ = {};
    psat_growth_exp_ = psat_scale_exp_ = local_factor_exp_ = {};
}

void Body::prepare(double dt_s, const Environment& env) {
    if (prepared_ && dt_s == dt_s_ && env.air_temp_c == env_.air_temp_c && env.mrt_c == env_.mrt_c &&
        env.rh_pct == env_.rh_pct && env.air_speed_m_s == env_.air_speed_m_s)
        return;
    require_in_range("relative humidity", env.rh_pct, 0.0, 100.0, "%");
    require_in_range("air temperature", env.air_temp_c, -40.0, 70.0, "degC");
    require_in_range("mean radiant temperature", env.mrt_c, -40.0, 150.0, "degC");
    require_in_range("air speed", env.air_speed_m_s, 0.0, 20.0, "m/s");
    // The fastest nodes (skin at full blood flow, 90 l/h) have time constants near 6 s.
    require_in_range("time step", dt_s, 1e-3, 5.0, "s");
    const bool seed = options_.seed_compatible;
    air_k_ = env.air_temp_c + 273.15;
    mrt_k_ = env.mrt_c + 273.15;
    const double rh = env.rh_pct / 100.0;
    p_air_pa_ = rh * psat_pa(air_k_);
    c_air_ = concentration(seed, psat_pa(air_k_), air_k_) * rh;
    const double area_total_m2 = std::accumulate(area_m2.begin(), area_m2.end(), 0.0);
    q_total_w_ = met_ * 58.15 * area_total_m2;
    q_work_w_ = std::max(q_total_w_ - basal_total_w, 0.0) * 0.78;
    // Divisions out of the step loop: dt / C per node, 1 / dt.
    for (int j = 0; j < node_count; ++j) step_per_capacity_s_k_j_[j] = dt_s / heat_capacity_j_k[j];
    per_step_1_s_ = 1.0 / dt_s;
    // pow() only when the speed changes (a square wave at most).
    if (!prepared_ || env.air_speed_m_s != env_.air_speed_m_s)
        for (int i = 0; i < segment_count; ++i)
            h_forced_w_m2k_[i] = env.air_speed_m_s > 0.0 ? forced_a[i] * std::pow(env.air_speed_m_s, forced_b[i]) : 0.0;
    env_ = env;
    dt_s_ = dt_s;
    prepared_ = true;
}

const StepState& Body::step(double dt_s, const Environment& env, const SegmentValues* measured_skin_loss_w) {
    prepare(dt_s, env);
    if (measured_skin_loss_w)
        for (double q : *measured_skin_loss_w)
            if (!std::isfinite(q) || std::abs(q) > 5000.0)
                throw std::domain_error("a measured segment heat loss must be finite and within ±5000 W");
    const bool seed = options_.seed_compatible;
    const auto& opt = options_;
    const double air_k = air_k_, mrt_k = mrt_k_, p_air_pa = p_air_pa_, c_air = c_air_;
    const double area_total_m2 = std::accumulate(area_m2.begin(), area_m2.end(), 0.0);
    const double q_total_w = q_total_w_, q_work_w = q_work_w_;
    const Segments& clothing_r_m2k_w = clothing_r_m2k_w_;
    const Segments& clothing_re_m2pa_w = clothing_re_m2pa_w_;
    const Segments& h_forced_w_m2k = h_forced_w_m2k_;
    auto conc = [seed](double p_pa, double t_k) { return concentration(seed, p_pa, t_k); };
    constexpr double ln2_over_30 = 0.69314718055994530942 / 30.0;
    Nodes& t_k = t_k_;
    StepState& out = state_;

    // The per-step arrays are left uninitialised where every element is written before it is
    // read: zeroing them was a tenth of a step (rep stos per array).
    Segments t_skin_k, h_conv, h_total, t_operative_k, f_cl;
    for (int i = 0; i < segment_count; ++i) t_skin_k[i] = t_k[skin(i)];

    // ---- Convection: free law, mixed with forced by Eq. 9 (n = 3) ----
    Segments c_skin, p_skin_pa;
    // The seed's mixed-index p_sat (D2 below) factors: exp(77.345 + 0.0057 T_j - 7235/T_i -
    // 8.2 ln T_i) = growth_j x scale_i, so its 36 terms per step cost 12 exp and 6 log, and
    // p_sat(T_i) itself is growth_i x scale_i.
    Segments psat_growth, psat_scale;  // written and read only in seed-compatible mode
    for (int i = 0; i < segment_count; ++i) {
        const double ln_t = ln_skin_k_[i](t_skin_k[i]);
        if (seed) {
            psat_growth[i] = psat_growth_exp_[i](0.0057 * t_skin_k[i]);
            psat_scale[i] = psat_scale_exp_[i](77.3450 - 7235.0 / t_skin_k[i] - 8.2 * ln_t);
            p_skin_pa[i] = psat_growth[i] * psat_scale[i];
        } else {
            p_skin_pa[i] = psat_scale_exp_[i](psat_exponent(t_skin_k[i], ln_t));  // psat_pa, stepwise
        }
        c_skin[i] = conc(p_skin_pa[i], t_skin_k[i]);
    }
    // Sums over j of the seed's direction terms that do not depend on i.
    double seed_dt_sum_k = 0.0, seed_growth_conc_sum = 0.0;
    if (seed)
        for (int j = 0; j < segment_count; ++j) {
            seed_dt_sum_k += t_skin_k[j] - air_k;
            seed_growth_conc_sum += conc(psat_growth[j], t_skin_k[j]);  // linear in p
        }
    double mean_drive_c = 0.0;  // mean over segments of dT + 146 dC (the flow direction)
    for (int j = 0; j < segment_count; ++j)
        mean_drive_c += ((t_skin_k[j] - air_k) + 146.0 * (c_skin[j] - c_air)) / segment_count;
    double reported_drive_c = mean_drive_c;
    for (int i = 0; i < segment_count; ++i) {
        double h_free = 0.0;
        switch (opt.convection) {
            case ConvectionModel::coupled: {
                double direction_c = mean_drive_c;
                if (seed) {
                    // The code's mean mixes loop indices: segment j's p_sat takes segment i's
                    // temperature in two of its three terms (docs/thermoregulation.md, D2).
                    // sum_j [(T_j - T_air) + 146 (C(growth_j scale_i, T_j) - C_air)] / 6
                    direction_c = (seed_dt_sum_k + 146.0 * (psat_scale[i] * seed_growth_conc_sum - 6.0 * c_air)) / 6.0;
                    reported_drive_c = direction_c;  // the code plots the value left by the last segment
                }
                const double drive_c = (t_skin_k[i] - air_k) + 146.0 * (c_skin[i] - c_air);
                h_free = coupled_h0[i] + (direction_c > 0.0 ? coupled_b_pos[i] : coupled_b_neg[i]) * quarter_power(drive_c);
                break;
            }
            case ConvectionModel::dt_only:
                h_free = wissler_a[i] * quarter_power(t_skin_k[i] - air_k);
                break;
            case ConvectionModel::constant_stolwijk: h_free = stolwijk_h[i]; break;
            case ConvectionModel::constant_jos: h_free = jos_h[i]; break;
        }
        const double h_forced = h_forced_w_m2k[i];
        // In still air the mix is the free law itself; cbrt was a tenth of the run time.
        h_conv[i] = h_forced == 0.0 ? h_free : std::cbrt(h_free * h_free * h_free + h_forced * h_forced * h_forced);
        f_cl[i] = 1.0 + 1.81 * clothing_r_m2k_w[i];
        h_total[i] = 1.0 / (clothing_r_m2k_w[i] + 1.0 / (f_cl[i] * (h_conv[i] + radiation_w_m2k[i])));
        t_operative_k[i] = (h_conv[i] * air_k + radiation_w_m2k[i] * mrt_k) / (h_conv[i] + radiation_w_m2k[i]);
    }

    // ---- Control: error signals, skin receptors, vasomotion, shivering, sweating (JOS-3) ----
    Nodes err;
    for (int j = 0; j < node_count; ++j) err[j] = t_k[j] - set_point_k[j];
    double warm_skin = 0.0, cold_skin = 0.0;
    for (int i = 0; i < segment_count; ++i) {
        warm_skin += std::max(err[skin(i)], 0.0) * df_receptors[i];
        cold_skin += std::max(-err[skin(i)], 0.0) * df_receptors[i];
    }
    const double vasodilation = std::max(100.5 * err[0] + 6.4 * (warm_skin - cold_skin), 0.0);
    const double vasoconstriction = std::max(-10.8 * err[0] - 10.8 * (warm_skin - cold_skin), 0.0);
    // The code's shivering goes negative when the head core is warm and the skin cold (D3).
    double shivering_w = 24.36 * -err[0] * cold_skin;
    if (!seed) shivering_w = std::max(shivering_w, 0.0);
    const double sweat_signal_w = std::max(371.2 * err[0] + 33.64 * (warm_skin - cold_skin), 0.0);

    Segments skin_blood_l_h, q_sweat_w, wettedness;
    for (int i = 0; i < segment_count; ++i) {
        const int k = skin(i);
        // 2^(e/6) and 2^(e/10) as powers of one 2^(e/30): one exp2 per segment, not two.
        const double local_factor = local_factor_exp_[i](err[k] * ln2_over_30);
        const double local_factor_sq = local_factor * local_factor;
        skin_blood_l_h[i] = std::min((basal_blood_flow_l_h[k] + df_vasodilation[i] * vasodilation) /
                                         (1.0 + df_vasoconstriction[i] * vasoconstriction) *
                                         (local_factor_sq * local_factor_sq * local_factor),
                                     90.0);
        const double h_evap = 1.0 / (clothing_re_m2pa_w[i] + 1.0 / (f_cl[i] * h_conv[i] * lewis_k_per_pa));
        const double dp_pa = p_skin_pa[i] - p_air_pa;
        const double q_max = h_evap * dp_pa * area_m2[i];
        double q = std::min(df_sweat[i] * sweat_signal_w * (local_factor_sq * local_factor), q_max);
        wettedness[i] = q_max != 0.0 ? 0.06 + 0.94 * q / q_max : 0.06;
        if (!seed) wettedness[i] = std::clamp(wettedness[i], 0.06, 1.0);
        q_sweat_w[i] = wettedness[i] * h_evap * dp_pa * area_m2[i];
    }

    // ---- Heat generation, conduction and blood flow per node ----
    Nodes q_w, blood_l_h, q_cond_w;  // q_cond_w of a skin node and blood_l_h of the central blood are never read
    for (int i = 0; i < segment_count; ++i) {
        const int k = 4 * i;
        q_w[k] = basal_metabolism_w[k];
        blood_l_h[k] = basal_blood_flow_l_h[k];
        q_w[k + 1] = basal_metabolism_w[k + 1] + df_shiver[i] * shivering_w + q_work_w * df_work[i];
        blood_l_h[k + 1] = basal_blood_flow_l_h[k + 1] + (q_w[k + 1] - basal_metabolism_w[k + 1]) / blood_heat_w_h_per_l_k;
        q_w[k + 2] = basal_metabolism_w[k + 2];
        blood_l_h[k + 2] = basal_blood_flow_l_h[k + 2];
        q_w[k + 3] = basal_metabolism_w[k + 3];
        blood_l_h[k + 3] = basal_blood_flow_l_h[k + 3] + skin_blood_l_h[i];
        for (int n = 0; n < 3; ++n) q_cond_w[k + n] = conductance_w_k[k + n] * (t_k[k + n] - t_k[k + n + 1]);
    }
    q_w[central_blood] = 0.0;  // no metabolism of its own
    const double production_w = sum_of(q_w.data(), node_count);
    Nodes q_blood_w;  // the central blood's own entry is never read
    for (int j = 0; j < central_blood; ++j)
        q_blood_w[j] = blood_heat_w_h_per_l_k * blood_l_h[j] * (t_k[j] - t_k[central_blood]);

    double skin_loss_total_w = 0.0, evaporation_loss_w = 0.0, conv_loss_w = 0.0, rad_loss_w = 0.0;
    for (int i = 0; i < segment_count; ++i) {
        const int k = 4 * i;
        const double sensible = h_total[i] * (t_skin_k[i] - t_operative_k[i]) * area_m2[i];
        out.modelled_loss_w[i] = sensible + q_sweat_w[i];
        // In the loop the manikin's measured loss stands for the model's exchange (sensible +
        // evaporative); the model's own split is kept for the report.
        const double skin_loss = measured_skin_loss_w ? (*measured_skin_loss_w)[i] : sensible + q_sweat_w[i];
        out.skin_loss_w[i] = skin_loss;
        q_w[k] -= q_blood_w[k] + q_cond_w[k];
        q_w[k + 1] += -q_blood_w[k + 1] + q_cond_w[k] - q_cond_w[k + 1];
        q_w[k + 2] += -q_blood_w[k + 2] + q_cond_w[k + 1] - q_cond_w[k + 2];
        q_w[k + 3] += measured_skin_loss_w ? -q_blood_w[k + 3] + q_cond_w[k + 2] - skin_loss
                                           : -q_blood_w[k + 3] + q_cond_w[k + 2] - q_sweat_w[i] - sensible;
        skin_loss_total_w += measured_skin_loss_w ? skin_loss : sensible;
        evaporation_loss_w += q_sweat_w[i];
        if (seed) {
            // The code splits convection and radiation at the skin temperature, ignoring the
            // clothing, so the two do not add up to the sensible loss on clothed segments (D4).
            conv_loss_w += h_conv[i] * (t_skin_k[i] - air_k) * area_m2[i];
            rad_loss_w += radiation_w_m2k[i] * (t_skin_k[i] - mrt_k) * area_m2[i];
        } else {
            // Split at the clothing surface, whose temperature the sensible flux fixes.
            const double t_surface_k = t_operative_k[i] + sensible / (area_m2[i] * f_cl[i] * (h_conv[i] + radiation_w_m2k[i]));
            conv_loss_w += f_cl[i] * h_conv[i] * (t_surface_k - air_k) * area_m2[i];
            rad_loss_w += f_cl[i] * radiation_w_m2k[i] * (t_surface_k - mrt_k) * area_m2[i];
        }
        out.evaporation_w[i] = q_sweat_w[i];
        out.sweat_rate_g_m2_h[i] = q_sweat_w[i] / area_m2[i] * 3600.0 / sweat_latent_heat_j_g;
        out.skin_blood_flow_l_h[i] = skin_blood_l_h[i];
    }
    const double respiration_w = (0.0014 * ((34.0 + 273.15) - air_k) + 0.0173 * (5.87 - p_air_pa / 1000.0)) * q_total_w;
    q_w[core_trunk] -= respiration_w;
    q_w[central_blood] = sum_of(q_blood_w.data(), central_blood);

    // ---- Explicit step ----
    Nodes t_new_k, storage_node_w;
    for (int j = 0; j < node_count; ++j) {
        t_new_k[j] = t_k[j] + q_w[j] * step_per_capacity_s_k_j_[j];
        if (!std::isfinite(t_new_k[j]) || std::abs(t_new_k[j] - t_k[j]) > 2.0)
            throw std::domain_error("the explicit scheme went unstable (a node moved more than 2 K in one step): "
                                    "use a shorter time step");
        storage_node_w[j] = heat_capacity_j_k[j] * (t_new_k[j] - t_k[j]) * per_step_1_s_;
    }
    const double storage_true_w = sum_of(storage_node_w.data(), node_count);
    // Measured: the skin's loss is already the whole exchange; modelled: sensible + evaporation.
    const double losses_w = measured_skin_loss_w ? skin_loss_total_w + respiration_w
                                                 : skin_loss_total_w + evaporation_loss_w + respiration_w;
    const double residual_w = storage_true_w - (production_w - losses_w);
    max_abs_residual_w_ = std::max(max_abs_residual_w_, std::abs(residual_w));

    OutputSample& s = out.sample;
    s = OutputSample{};
    s.t_s = time_s_;
    s.core_temp_c = t_new_k[core_trunk] - 273.15;
    for (int i = 0; i < segment_count; ++i) {
        s.mean_skin_temp_c += t_new_k[skin(i)] * area_m2[i] / area_total_m2;
        s.mean_skin_wettedness += wettedness[i] * area_m2[i] / area_total_m2;
        out.skin_temp_c[i] = t_new_k[skin(i)] - 273.15;
        out.core_temp_c[i] = t_new_k[4 * i] - 273.15;
    }
    s.mean_skin_temp_c -= 273.15;
    s.convection_w = -conv_loss_w;
    s.radiation_w = -rad_loss_w;
    s.evaporation_w = -evaporation_loss_w;
    s.respiration_w = -respiration_w;
    // The code plots met x area x 58 as "heat generation" and computes storage with
    // Q_total - 0.22 Q_work as production (D5); the default reports what the nodes get.
    s.metabolic_w = seed ? met_ * area_total_m2 * 58.0 : production_w;
    const double sensible_w = measured_skin_loss_w ? skin_loss_total_w - evaporation_loss_w : skin_loss_total_w;
    s.storage_w = seed ? q_total_w - 0.22 * q_work_w - evaporation_loss_w - sensible_w - respiration_w : storage_true_w;
    s.mean_buoyancy_drive_c = reported_drive_c;
    s.energy_residual_w = residual_w;
    t_k = t_new_k;
    time_s_ += dt_s;
    return out;
}

SimulationResult simulate(const Exposure& e, const ModelOptions& opt) {
    validate(e);
    Body body(e.met, opt);
    const auto steps = static_cast<long>(std::llround(e.duration_s / e.time_step_s)) + 1;
    const auto output_every = static_cast<long>(std::llround(e.output_interval_s / e.time_step_s));
    SimulationResult result;
    Environment env{e.air_temp_c, e.mrt_c, e.rh_pct, 0.0};
    for (long step = 0; step < steps; ++step) {
        const double time_s = static_cast<double>(step) * e.time_step_s;
        env.air_speed_m_s = e.air_speed.at(time_s);
        const StepState& st = body.step(e.time_step_s, env);
        if (step % output_every == 0 || step == steps - 1) {
            OutputSample s = st.sample;
            s.t_s = time_s;
            if (step % output_every == 0) result.series.push_back(s);
            result.final = s;
        }
    }
    result.max_abs_energy_residual_w = body.max_abs_energy_residual_w();
    result.final_node_temps_c = body.node_temps_c();
    return result;
}

}  // namespace manikind::physics::thermoreg
