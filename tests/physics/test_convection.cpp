#include <catch2/catch.hpp>

#include <cmath>

#include "physics/air_properties.hpp"
#include "physics/buoyancy.hpp"
#include "physics/convection.hpp"
#include "physics/paper_cfd_table.hpp"
#include "physics/threshold_map.hpp"
#include "tests/physics/paper_csv.hpp"

using namespace manikind::physics;

namespace {
BuoyancyResult cfd_buoyancy(const CfdCase& c) {
    SkinAirState s;
    s.skin_temp_c = cfd_skin_temp_c;
    s.air_temp_c = c.air_temp_c;
    s.air_rh_pct = c.air_rh_pct;
    return buoyancy(s);
}
}  // namespace

TEST_CASE("Eq. 8 vs the CFD table: mean error -2.6 %, MAE 7.7 %, RMSE 13.3 %", "[physics][convection]") {
    double sum = 0.0, sum_abs = 0.0, sum_sq = 0.0;
    int n = 0;
    for (const auto& c : paper_cfd_cases()) {
        const auto b = cfd_buoyancy(c);
        const double error_pct = 100.0 * (c.h_sim_w_m2k - h_eq8_w_m2k(b.dt_c, b.dc_kg_m3)) / c.h_sim_w_m2k;
        sum += error_pct;
        sum_abs += std::abs(error_pct);
        sum_sq += error_pct * error_pct;
        ++n;
    }
    // The paper's sign: (simulated - Eq. 8) / simulated. Its fit used 100 cases; the table has 90.
    CHECK(sum / n == Approx(-2.6).margin(0.1));
    CHECK(sum_abs / n == Approx(7.7).margin(0.2));
    CHECK(std::sqrt(sum_sq / n) == Approx(13.3).margin(0.3));
}

TEST_CASE("Eq. S8 reproduces the table's h_dT-only column (exponent 0.29 when air is hotter)", "[physics][convection]") {
    int hot_rows_off_eq_s8 = 0;
    for (const auto& c : paper_cfd_cases()) {
        INFO("case " << c.case_id << ", dT = " << c.dt_skin_air_c);
        CHECK(h_dt_only_table_s8_w_m2k(c.dt_skin_air_c) == Approx(c.h_dt_only_w_m2k).margin(0.0051));
        if (c.dt_skin_air_c > 0.0) CHECK(h_dt_only_w_m2k(c.dt_skin_air_c) == Approx(c.h_dt_only_w_m2k).margin(0.0051));
        else if (std::abs(h_dt_only_w_m2k(c.dt_skin_air_c) - c.h_dt_only_w_m2k) > 0.0051) ++hot_rows_off_eq_s8;
    }
    // Eq. S8 as printed (0.3) misses most hot-air rows of the table: the finding documented in docs/physics.md.
    CHECK(hot_rows_off_eq_s8 > 30);
}

TEST_CASE("Results: h_sim is 56 % below h_dT-only at 41 C / 10 % RH, Eq. 8 sees the dip", "[physics][convection]") {
    int found = 0;
    for (const auto& c : paper_cfd_cases()) {
        if (c.case_id != 8) continue;  // 41 C, 10 %
        ++found;
        // 56.4 % in the text; 55.9 % from the rounded table values.
        CHECK(1.0 - c.h_sim_w_m2k / c.h_dt_only_w_m2k == Approx(0.564).margin(0.006));
        const auto b = cfd_buoyancy(c);
        // Near stagnation Eq. 8 errs most (Discussion), yet it is far closer than Eq. S8.
        CHECK(std::abs(h_eq8_w_m2k(b.dt_c, b.dc_kg_m3) - c.h_sim_w_m2k) <
              0.5 * std::abs(h_dt_only_table_s8_w_m2k(b.dt_c) - c.h_sim_w_m2k));
    }
    CHECK(found == 1);
}

TEST_CASE("Eq. 6: B = k C L^3/4 (g beta_T)^1/4 / (L (nu alpha)^1/4) = 1.255 at 35 C", "[physics][convection]") {
    const auto p = air_properties(35.0).properties;
    const double b = p.conductivity_w_m_k * 0.574 * std::pow(1.8, -0.25) *
                     std::pow(9.81 * p.thermal_expansion_1_k / (p.kinematic_viscosity_m2_s * p.thermal_diffusivity_m2_s), 0.25);
    CHECK(b == Approx(1.255).epsilon(0.01));
    // Eq. 5 with the same properties equals Eq. 7 with that B and h0 = Nu0 k/L.
    SkinAirState s;
    s.skin_temp_c = 35.0;
    s.air_temp_c = 35.0;
    s.air_rh_pct = 10.0;
    const auto bu = buoyancy(s);
    const double h_eq5 = h_from_nusselt_w_m2k(nusselt_eq5(bu.ra_total), p.conductivity_w_m_k);
    const double h0 = 17.27 * p.conductivity_w_m_k / 1.8;
    CHECK(h_eq5 == Approx(h_eq7_w_m2k(bu.dt_c, bu.dc_kg_m3, h0, b, bu.coupling_coefficient)).epsilon(0.002));
}

TEST_CASE("Discussion: thermally driven whole-body h is ~10 % above the turbulent vertical plate (Eq. 4)", "[physics][convection]") {
    SkinAirState s;
    s.skin_temp_c = 35.0;
    s.air_temp_c = 25.0;
    s.air_rh_pct = 50.0;
    s.skin_wettedness = 0.0;
    const auto b = buoyancy(s);
    const double h_plate = h_from_nusselt_w_m2k(nusselt_vertical_plate_turbulent(b.ra_dt),
                                                air_properties(b.film_temp_c).properties.conductivity_w_m_k);
    const double ratio = h_dt_only_w_m2k(b.dt_c) / h_plate;
    CHECK(ratio == Approx(1.1).margin(0.05));
    // Eq. 3 (laminar) at the same Ra is within 10 % of the turbulent one in this range (Fig. 3A overlap).
    const double h_lam = h_from_nusselt_w_m2k(nusselt_vertical_plate_laminar(b.ra_dt),
                                              air_properties(b.film_temp_c).properties.conductivity_w_m_k);
    CHECK(h_lam / h_plate == Approx(1.0).margin(0.1));
}

TEST_CASE("Table 1 in code equals the paper's CSV", "[physics][convection]") {
    for (const auto& row : manikind::test::read_paper_csv("segment_coefficients_table1.csv")) {
        const auto seg = parse_segment(row.at("segment"));
        REQUIRE(seg.has_value());
        const auto c = segment_coefficients(*seg);
        INFO(row.at("segment"));
        CHECK(c.h0_w_m2k == Approx(manikind::test::num(row, "h0_pos")));
        CHECK(c.b_pos == Approx(manikind::test::num(row, "b_pos")));
        CHECK(c.sigma_b_pos == Approx(manikind::test::num(row, "sigma_b_pos")));
        if (row.at("b_neg").empty()) {
            CHECK_FALSE(c.b_neg_printed);
        } else {
            CHECK(c.b_neg == Approx(manikind::test::num(row, "b_neg")));
            CHECK(c.sigma_b_neg == Approx(manikind::test::num(row, "sigma_b_neg")));
        }
    }
}

TEST_CASE("Table 1: sign of N = dT + 146 dC picks B, h0 is continuous at N = 0", "[physics][convection]") {
    // Thigh: B+ = 1.166, B- = 0.654 (Table 1).
    CHECK(h_segment_w_m2k(Segment::thigh, 16.0, 0.0) == Approx(0.538 + 1.166 * 2.0));
    CHECK(h_segment_w_m2k(Segment::thigh, -16.0, 0.0) == Approx(0.538 + 0.654 * 2.0));
    CHECK(h_segment_w_m2k(Segment::thigh, -1.46, 0.01) == Approx(0.538).margin(1e-9));
}

TEST_CASE("Table 2 in code equals the paper's CSV (printed and MATLAB B values)", "[physics][convection]") {
    const std::pair<const char*, const char*> names[] = {{"head", "head"}, {"torso", "torso"}, {"arms", "arms"},
                                                         {"hands", "hands"}, {"legs", "legs"}, {"feet", "feet"}};
    const auto rows = manikind::test::read_paper_csv("regional_models_table2.csv");
    REQUIRE(rows.size() == 6);
    for (const auto& row : rows) {
        const auto region = parse_region(row.at("zone"));
        REQUIRE(region.has_value());
        INFO(row.at("zone"));
        CHECK(h_regional_w_m2k(RegionalModel::stolwijk, *region, 5.0, 0.0) == Approx(manikind::test::num(row, "stolwijk_hc")));
        CHECK(h_regional_w_m2k(RegionalModel::jos, *region, 5.0, 0.0) == Approx(manikind::test::num(row, "jos_hc")));
        CHECK(h_regional_w_m2k(RegionalModel::wissler, *region, 16.0, 0.0) == Approx(2.0 * manikind::test::num(row, "wissler_a")));
        const double h0 = manikind::test::num(row, "h0");
        CHECK(h_regional_w_m2k(RegionalModel::present_study, *region, 16.0, 0.0) == Approx(h0 + 2.0 * manikind::test::num(row, "b_pos")));
        CHECK(h_regional_w_m2k(RegionalModel::present_study, *region, -16.0, 0.0) == Approx(h0 + 2.0 * manikind::test::num(row, "b_neg")));
        CHECK(h_regional_w_m2k(RegionalModel::seed_code, *region, 16.0, 0.0) == Approx(h0 + 2.0 * manikind::test::num(row, "matlab_b_pos")));
        CHECK(h_regional_w_m2k(RegionalModel::seed_code, *region, -16.0, 0.0) == Approx(h0 + 2.0 * manikind::test::num(row, "matlab_b_neg")));
    }
    (void)names;
}

TEST_CASE("Text S6.2: seated and supine whole-body h, standing is Eq. 8 with dC = 0", "[physics][convection]") {
    CHECK(h_posture_w_m2k(Posture::seated, 16.0) == Approx(0.48 + 1.19 * 2.0));
    CHECK(h_posture_w_m2k(Posture::supine, -16.0) == Approx(0.34 + 1.46 * 2.0));
    CHECK(h_posture_w_m2k(Posture::standing, 16.0) == Approx(0.3 + 1.25 * 2.0));
}

TEST_CASE("Discussion: h_mix/h_F <= 1.05 and 1.1 mean h_c/h_F <= 0.54 and 0.69 (Eq. 9, n = 3)", "[physics][convection]") {
    CHECK(max_free_to_forced_ratio(1.05) == Approx(0.54).margin(0.005));
    CHECK(max_free_to_forced_ratio(1.1) == Approx(0.69).margin(0.005));
    const double h_f = h_forced_de_dear_w_m2k(0.2);
    CHECK(h_mixed_w_m2k(0.54 * h_f, h_f) / h_f == Approx(1.05).margin(0.001));
    CHECK(h_mixed_w_m2k(h_f, h_f, 3.0, true) == Approx(0.0).margin(1e-9));
}

TEST_CASE("Fig. 3C: minimum threshold speed near the neutral-buoyancy line is ~0.03 m/s", "[physics][convection]") {
    // On the paper's 1 C x 10 % grid (Tables S8-S10 resolution) the minimum is 0.027 m/s at 40 C / 10 %.
    ThresholdGrid grid;
    const auto coarse = minimum_threshold_on_grid(grid);
    CHECK(coarse.speed_m_s == Approx(0.03).margin(0.005));
    // Exactly on the line h_c = h0 = 0.3, so the continuous minimum is lower (0.005 m/s):
    // the paper's 0.03 is a property of its grid. Documented in docs/physics.md.
    CHECK(threshold_air_speed_m_s(0.3) == Approx(std::pow(0.3 / (0.5402 * 10.4), 1.0 / 0.56)).epsilon(1e-3));
    grid.air_temp_step_c = 0.1;
    grid.rh_step_pct = 1.0;
    CHECK(minimum_threshold_on_grid(grid).speed_m_s < coarse.speed_m_s);
}

TEST_CASE("Fig. 3C / S21: most thresholds lie below 0.3 m/s, with 1.1 the top drops to 0.225 m/s", "[physics][convection]") {
    // The figure's axis is not printed; 0.225 m/s is the 1.1-criterion top when the grid starts at
    // 15 C air (it is 0.205 m/s from 20 C). Inference documented in docs/physics.md.
    double top_11 = 0.0;
    int below_03 = 0, points = 0;
    for (double t = 15.0; t <= 50.0; t += 1.0)
        for (double rh = 10.0; rh <= 90.0; rh += 10.0) {
            const double v105 = threshold_point(t, rh, 35.0, 1.05, FreeConvectionLaw::eq8).speed_m_s;
            below_03 += v105 < 0.3 ? 1 : 0;
            ++points;
            top_11 = std::max(top_11, threshold_point(t, rh, 35.0, 1.1, FreeConvectionLaw::eq8).speed_m_s);
        }
    CHECK(below_03 > points / 2);  // "most": 79 % of this grid
    CHECK(top_11 == Approx(0.225).margin(0.005));
}

TEST_CASE("Forced convection: de Dear 10.4 v^0.56 and the MATLAB regional fits", "[physics][convection]") {
    CHECK(h_forced_de_dear_w_m2k(1.0) == Approx(10.4));
    CHECK(h_forced_regional_w_m2k(Region::torso, 1.0) == Approx(8.1));
    CHECK(h_forced_regional_w_m2k(Region::head, 0.5) == Approx(3.20 * std::pow(0.5, 0.97)));
    CHECK_THROWS_AS(h_forced_de_dear_w_m2k(-0.1), std::domain_error);
}
