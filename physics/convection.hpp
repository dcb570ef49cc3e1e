#pragma once
// Free, forced and mixed convection coefficients for the human body, W/(m²·K).
// dt_c = T_skin - T_air (°C), dc_kg_m3 = C_skin - C_air (kg/m³); positive drive = ascending plume.

#include <optional>
#include <string_view>

namespace manikind::physics {

// ---- Whole-body free convection -------------------------------------------------------------

// Eq. S8: h = 1.36 |dT|^0.3 (the "temperature-difference only" correlation, dry skin).
double h_dt_only_w_m2k(double dt_c);

// The h_dT-only column of the paper's CFD table (Tables S8-S10) follows Eq. S8 only for
// T_air < T_skin; for T_air > T_skin it is reproduced to its printed precision by exponent 0.29
// (our finding; the paper prints only Eq. S8). Kept separate so Eq. S8 stays as printed.
double h_dt_only_table_s8_w_m2k(double dt_c);

// Eq. 3: laminar vertical plate Nu = 0.59 Ra^(1/4) (stated for 1e4 < Ra < 1e9).
double nusselt_vertical_plate_laminar(double rayleigh);
// Eq. 4: turbulent vertical plate Nu = 0.1 Ra^(1/3) (stated for 1e9 < Ra < 1e13).
double nusselt_vertical_plate_turbulent(double rayleigh);
// Eq. 5: Nu = Nu0 + C |Ra_T|^(1/4); fitted Nu0 = 17.27 ± 3.91, C = 0.574 ± 0.018 (68 % CI).
double nusselt_eq5(double rayleigh_total, double nu0 = 17.27, double c = 0.574);
// h = Nu k / L.
double h_from_nusselt_w_m2k(double nusselt, double conductivity_w_m_k, double length_m = 1.8);

// Eq. 7: h = h0 + B |dT + gamma dC|^(1/4). gamma = beta_C alpha/(beta_T D) ~ 146.
double h_eq7_w_m2k(double dt_c, double dc_kg_m3, double h0_w_m2k, double b, double gamma = 146.0);
// Eq. 8: whole body, standing: h = 0.3 + 1.25 |dT + 146 dC|^(1/4).
double h_eq8_w_m2k(double dt_c, double dc_kg_m3);
// The coupled buoyancy drive N = dT + gamma dC, °C (Table 2 caption).
double buoyancy_drive_c(double dt_c, double dc_kg_m3, double gamma = 146.0);

enum class Posture { standing, seated, supine };
// Text S6.2 (dry skin): seated 0.48 + 1.19 |dT|^(1/4), supine 0.34 + 1.46 |dT|^(1/4);
// standing is Eq. 8 with dC = 0.
double h_posture_w_m2k(Posture posture, double dt_c);
std::optional<Posture> parse_posture(std::string_view name);

// ---- Segmental and regional free convection -------------------------------------------------

// Table 1 segments (plus the hand, Eq. S12).
enum class Segment {
    head, chest, back, whole_torso, upper_arm, forearm, whole_arm, pelvis, thigh, calf, whole_leg,
    foot, hand
};
std::optional<Segment> parse_segment(std::string_view name);
std::string_view segment_name(Segment segment);

struct SignedCoefficients {
    double h0_w_m2k = 0.0;
    double b_pos = 0.0;        // N > 0 (ascending)
    double b_neg = 0.0;        // N < 0 (descending)
    double sigma_b_pos = 0.0;  // standard errors as printed (0 where not printed)
    double sigma_b_neg = 0.0;
    bool b_neg_printed = true; // false: Table 1's chest row prints no N < 0 fit (see .cpp)
};
SignedCoefficients segment_coefficients(Segment segment);

// Table 1 with the sign of N = dT + 146 dC choosing B (Discussion: h0 shared by both signs).
double h_segment_w_m2k(Segment segment, double dt_c, double dc_kg_m3);

// Table 2 regions and models.
enum class Region { head, torso, arms, hands, legs, feet };
enum class RegionalModel {
    stolwijk,       // constant h_c (Stolwijk 1971)
    jos,            // constant h_c (JOS-2 & JOS-3)
    wissler,        // A |dT|^(1/4)
    present_study,  // Table 2 as printed: h0 + B± |dT + 146 dC|^(1/4)
    seed_code       // the same form with the MATLAB code's B values (arms B+ = 1.278, head B- = 1.4, torso B- = 1.03)
};
std::optional<Region> parse_region(std::string_view name);
std::string_view region_name(Region region);
std::optional<RegionalModel> parse_regional_model(std::string_view name);
double h_regional_w_m2k(RegionalModel model, Region region, double dt_c, double dc_kg_m3);

// ---- Forced and mixed convection ------------------------------------------------------------

// de Dear et al.: h_F = 10.4 v^0.56 (not validated below 0.2 m/s, Discussion).
double h_forced_de_dear_w_m2k(double air_speed_m_s);
// Regional forced coefficients of the MATLAB code: h_F = a v^b per Table 2 region.
double h_forced_regional_w_m2k(Region region, double air_speed_m_s);
// Eq. 9: h_mix = (h_c^n + h_F^n)^(1/n) when the flows assist; |h_c^n - h_F^n|^(1/n) when they oppose.
double h_mixed_w_m2k(double h_free_w_m2k, double h_forced_w_m2k, double n = 3.0, bool opposing = false);
// From h_mix/h_F = (1 + (h_c/h_F)^n)^(1/n): the largest h_c/h_F keeping h_mix/h_F <= ratio
// (1.05 -> 0.54, 1.1 -> 0.69, Discussion).
double max_free_to_forced_ratio(double mix_to_forced_ratio, double n = 3.0);
// Air speed at which h_mix/h_F falls to mix_to_forced_ratio (Fig. 3C), using de Dear's h_F.
double threshold_air_speed_m_s(double h_free_w_m2k, double mix_to_forced_ratio = 1.05, double n = 3.0);

}  // namespace manikind::physics
