#include "physics/convection.hpp"

#include <array>
#include <cmath>
#include <cstddef>

#include "physics/range_check.hpp"

namespace manikind::physics {
namespace {

double quarter_power(double x) { return std::pow(std::abs(x), 0.25); }

struct Table1Row {
    Segment segment;
    std::string_view name;
    SignedCoefficients c;
};

// Table 1 (h0, B and sigma_B for both buoyancy regimes). The chest row prints its h0 (0.227)
// in every N < 0 column, i.e. no negative-regime fit was printed; we fall back to the whole
// torso's B = 1.025 there and flag it. The hand comes from Eq. S12 (h0 = 0.5, B = 2.4), which
// Table 2 uses for both signs.
constexpr std::array<Table1Row, 13> table1{{
    {Segment::head, "head", {0.567, 1.036, 1.398, 0.032, 0.029, true}},
    {Segment::chest, "chest", {0.227, 0.958, 1.025, 0.022, 0.0, false}},
    {Segment::back, "back", {0.248, 0.940, 1.173, 0.022, 0.026, true}},
    {Segment::whole_torso, "whole_torso", {0.290, 0.996, 1.025, 0.023, 0.024, true}},
    {Segment::upper_arm, "upper_arm", {0.854, 1.158, 1.187, 0.031, 0.033, true}},
    {Segment::forearm, "forearm", {1.116, 1.535, 1.114, 0.038, 0.033, true}},
    {Segment::whole_arm, "whole_arm", {0.937, 1.278, 1.164, 0.033, 0.033, true}},
    {Segment::pelvis, "pelvis", {0.360, 1.061, 0.872, 0.025, 0.021, true}},
    {Segment::thigh, "thigh", {0.538, 1.166, 0.654, 0.028, 0.017, true}},
    {Segment::calf, "calf", {0.608, 1.291, 0.596, 0.033, 0.015, true}},
    {Segment::whole_leg, "whole_leg", {0.575, 1.233, 0.623, 0.031, 0.016, true}},
    {Segment::foot, "foot", {1.151, 1.673, 0.831, 0.051, 0.032, true}},
    {Segment::hand, "hand", {0.5, 2.4, 2.4, 0.0, 0.0, true}},
}};

struct Table2Row {
    Region region;
    std::string_view name;
    double stolwijk_w_m2k;
    double jos_w_m2k;
    double wissler_a;
    double h0_w_m2k;
    double b_pos;
    double b_neg;
    double seed_b_pos;  // MATLAB hc_e
    double seed_b_neg;  // MATLAB hc_g
    double forced_a;    // MATLAB hc_a (de Dear regional)
    double forced_b;    // MATLAB hc_b
};

// Table 2, plus the MATLAB code's own B values and regional forced-convection fits.
constexpr std::array<Table2Row, 6> table2{{
    {Region::head, "head", 0.660, 4.480, 2.600, 0.567, 1.036, 1.398, 1.036, 1.4, 3.20, 0.97},
    {Region::torso, "torso", 1.860, 2.910, 1.500, 0.290, 0.996, 1.025, 0.996, 1.03, 8.1, 0.62},
    {Region::arms, "arms", 3.950, 3.590, 1.900, 0.937, 1.535, 1.164, 1.278, 1.164, 11.09, 0.59},
    {Region::hands, "hands", 6.050, 3.670, 2.700, 0.500, 2.400, 2.400, 2.4, 2.4, 14.40, 0.55},
    {Region::legs, "legs", 3.610, 2.530, 2.150, 0.575, 1.233, 0.623, 1.233, 0.623, 11.10, 0.51},
    {Region::feet, "feet", 5.930, 2.040, 1.570, 1.151, 1.673, 0.831, 1.673, 0.831, 12.00, 0.49},
}};

const Table2Row& table2_row(Region region) { return table2[static_cast<std::size_t>(region)]; }

}  // namespace

double h_dt_only_w_m2k(double dt_c) { return 1.36 * std::pow(std::abs(dt_c), 0.3); }

double h_dt_only_table_s8_w_m2k(double dt_c) {
    return 1.36 * std::pow(std::abs(dt_c), dt_c < 0.0 ? 0.29 : 0.3);
}

double nusselt_vertical_plate_laminar(double rayleigh) { return 0.59 * quarter_power(rayleigh); }

double nusselt_vertical_plate_turbulent(double rayleigh) {
    return 0.1 * std::cbrt(std::abs(rayleigh));
}

double nusselt_eq5(double rayleigh_total, double nu0, double c) {
    return nu0 + c * quarter_power(rayleigh_total);
}

double h_from_nusselt_w_m2k(double nusselt, double conductivity_w_m_k, double length_m) {
    return nusselt * conductivity_w_m_k / length_m;
}

double buoyancy_drive_c(double dt_c, double dc_kg_m3, double gamma) { return dt_c + gamma * dc_kg_m3; }

double h_eq7_w_m2k(double dt_c, double dc_kg_m3, double h0_w_m2k, double b, double gamma) {
    return h0_w_m2k + b * quarter_power(buoyancy_drive_c(dt_c, dc_kg_m3, gamma));
}

double h_eq8_w_m2k(double dt_c, double dc_kg_m3) { return h_eq7_w_m2k(dt_c, dc_kg_m3, 0.3, 1.25, 146.0); }

double h_posture_w_m2k(Posture posture, double dt_c) {
    switch (posture) {
        case Posture::seated: return 0.48 + 1.19 * quarter_power(dt_c);
        case Posture::supine: return 0.34 + 1.46 * quarter_power(dt_c);
        case Posture::standing: break;
    }
    return h_eq8_w_m2k(dt_c, 0.0);
}

std::optional<Posture> parse_posture(std::string_view name) {
    if (name == "standing") return Posture::standing;
    if (name == "seated") return Posture::seated;
    if (name == "supine") return Posture::supine;
    return std::nullopt;
}

std::optional<Segment> parse_segment(std::string_view name) {
    for (const auto& row : table1)
        if (row.name == name) return row.segment;
    return std::nullopt;
}

std::string_view segment_name(Segment segment) { return table1[static_cast<std::size_t>(segment)].name; }

SignedCoefficients segment_coefficients(Segment segment) {
    return table1[static_cast<std::size_t>(segment)].c;
}

double h_segment_w_m2k(Segment segment, double dt_c, double dc_kg_m3) {
    const SignedCoefficients c = segment_coefficients(segment);
    const double drive_c = buoyancy_drive_c(dt_c, dc_kg_m3);
    return c.h0_w_m2k + (drive_c >= 0.0 ? c.b_pos : c.b_neg) * quarter_power(drive_c);
}

std::optional<Region> parse_region(std::string_view name) {
    for (const auto& row : table2)
        if (row.name == name) return row.region;
    return std::nullopt;
}

std::string_view region_name(Region region) { return table2_row(region).name; }

std::optional<RegionalModel> parse_regional_model(std::string_view name) {
    if (name == "stolwijk") return RegionalModel::stolwijk;
    if (name == "jos") return RegionalModel::jos;
    if (name == "wissler") return RegionalModel::wissler;
    if (name == "present" || name == "present_study" || name == "eq8") return RegionalModel::present_study;
    if (name == "seed" || name == "seed_code") return RegionalModel::seed_code;
    return std::nullopt;
}

double h_regional_w_m2k(RegionalModel model, Region region, double dt_c, double dc_kg_m3) {
    const Table2Row& row = table2_row(region);
    const double drive_c = buoyancy_drive_c(dt_c, dc_kg_m3);
    switch (model) {
        case RegionalModel::stolwijk: return row.stolwijk_w_m2k;
        case RegionalModel::jos: return row.jos_w_m2k;
        case RegionalModel::wissler: return row.wissler_a * quarter_power(dt_c);
        case RegionalModel::present_study:
            return row.h0_w_m2k + (drive_c >= 0.0 ? row.b_pos : row.b_neg) * quarter_power(drive_c);
        case RegionalModel::seed_code:
            return row.h0_w_m2k + (drive_c >= 0.0 ? row.seed_b_pos : row.seed_b_neg) * quarter_power(drive_c);
    }
    return 0.0;
}

double h_forced_de_dear_w_m2k(double air_speed_m_s) {
    require_in_range("air speed", air_speed_m_s, 0.0, 100.0, "m/s");
    return 10.4 * std::pow(air_speed_m_s, 0.56);
}

double h_forced_regional_w_m2k(Region region, double air_speed_m_s) {
    require_in_range("air speed", air_speed_m_s, 0.0, 100.0, "m/s");
    const Table2Row& row = table2_row(region);
    return row.forced_a * std::pow(air_speed_m_s, row.forced_b);
}

double h_mixed_w_m2k(double h_free_w_m2k, double h_forced_w_m2k, double n, bool opposing) {
    const double free_n = std::pow(h_free_w_m2k, n);
    const double forced_n = std::pow(h_forced_w_m2k, n);
    return std::pow(opposing ? std::abs(free_n - forced_n) : free_n + forced_n, 1.0 / n);
}

double max_free_to_forced_ratio(double mix_to_forced_ratio, double n) {
    require_in_range("h_mix/h_F ratio", mix_to_forced_ratio, 1.0, 10.0, "");
    return std::pow(std::pow(mix_to_forced_ratio, n) - 1.0, 1.0 / n);
}

double threshold_air_speed_m_s(double h_free_w_m2k, double mix_to_forced_ratio, double n) {
    // h_F(v) = h_c / (h_c/h_F)_max, then invert h_F = 10.4 v^0.56.
    const double h_forced_needed = h_free_w_m2k / max_free_to_forced_ratio(mix_to_forced_ratio, n);
    return std::pow(h_forced_needed / 10.4, 1.0 / 0.56);
}

}  // namespace manikind::physics
