#include <catch2/catch.hpp>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>
#include <stdexcept>

#include "physics/thermoreg/stolwijk.hpp"

using namespace manikind::physics::thermoreg;

namespace {
SimulationResult run(ConvectionModel m, bool seed, double mrt_c = 55.0, double speed_m_s = 0.0, double period_s = 0.0) {
    Exposure e;  // Fig. 4 defaults: 41 C, 20 %, 1.5 met, 2 h
    e.mrt_c = mrt_c;
    e.air_speed.speed_m_s = speed_m_s;
    e.air_speed.square_wave_period_s = period_s;
    ModelOptions o;
    o.convection = m;
    o.seed_compatible = seed;
    return simulate(e, o);
}
const OutputSample& at_minute(const SimulationResult& r, double minute) {
    for (const auto& s : r.series)
        if (std::abs(s.t_s - 60.0 * minute) < 1e-9) return s;
    throw std::runtime_error("no sample at that minute");
}
}  // namespace

TEST_CASE("Fig. 4C-D (seed-compatible): coupled model core 38.9 C and mean skin 38.5 C after 120 min", "[physics][thermoreg]") {
    const auto r = run(ConvectionModel::coupled, true);
    CHECK(r.final.t_s == 7200.0);
    CHECK(r.final.core_temp_c == Approx(38.9).margin(0.1));
    CHECK(r.final.mean_skin_temp_c == Approx(38.5).margin(0.1));
    // Discussion: dT + 146 dC stays between -1 and 0.5 C in this run (the near-stagnant plume).
    for (const auto& s : r.series)
        if (s.t_s >= 1200.0) CHECK(std::abs(s.mean_buoyancy_drive_c) < 1.5);
}

TEST_CASE("Fig. 4 text (seed-compatible): coupled model 38.3 C core and 37.9 C skin after 60 min (we get 38.1 / 37.7)", "[physics][thermoreg]") {
    const auto r = run(ConvectionModel::coupled, true);  // keep the result alive: at_minute returns into it
    const auto& s = at_minute(r, 60.0);
    CHECK(s.core_temp_c == Approx(38.3).margin(0.25));
    CHECK(s.mean_skin_temp_c == Approx(37.9).margin(0.3));
}

TEST_CASE("Fig. 4A-B (seed-compatible): temperature-only model core 37.9 C and skin 37.0 C after 120 min", "[physics][thermoreg]") {
    const auto r = run(ConvectionModel::dt_only, true);
    CHECK(r.final.core_temp_c == Approx(37.9).margin(0.1));
    CHECK(r.final.mean_skin_temp_c == Approx(37.0).margin(0.1));
    // "after 40 minutes ... stabilise": the last 80 min move little
    CHECK(std::abs(r.final.core_temp_c - at_minute(r, 40.0).core_temp_c) < 0.25);
    // the headline: neglecting humidity buoyancy underpredicts core by ~1 C and skin by ~1.5 C
    const auto coupled = run(ConvectionModel::coupled, true);
    CHECK(coupled.final.core_temp_c - r.final.core_temp_c == Approx(1.0).margin(0.1));
    CHECK(coupled.final.mean_skin_temp_c - r.final.mean_skin_temp_c == Approx(1.5).margin(0.1));
}

TEST_CASE("Fig. 4 text (seed-compatible): with MRT = air both models give core ~37.7 C, skins within 0.2 C", "[physics][thermoreg]") {
    const auto coupled = run(ConvectionModel::coupled, true, 41.0);
    const auto dt_only = run(ConvectionModel::dt_only, true, 41.0);
    CHECK(coupled.final.core_temp_c == Approx(37.7).margin(0.1));
    CHECK(dt_only.final.core_temp_c == Approx(37.7).margin(0.1));
    CHECK(std::abs(coupled.final.mean_skin_temp_c - dt_only.final.mean_skin_temp_c) <= 0.2);
}

TEST_CASE("Discussion: constant h_c (Stolwijk) and temperature-only predictions differ by less than 0.15 C", "[physics][thermoreg]") {
    const auto constant = run(ConvectionModel::constant_stolwijk, true);
    const auto dt_only = run(ConvectionModel::dt_only, true);
    CHECK(std::abs(constant.final.core_temp_c - dt_only.final.core_temp_c) < 0.15);
    CHECK(std::abs(constant.final.mean_skin_temp_c - dt_only.final.mean_skin_temp_c) < 0.15);
}

TEST_CASE("Thermoregulation: energy balance closes at every step (storage = production - losses)", "[physics][thermoreg]") {
    for (bool seed : {true, false})
        for (auto m : {ConvectionModel::coupled, ConvectionModel::dt_only, ConvectionModel::constant_jos}) {
            const auto r = run(m, seed, 55.0, 0.2, 60.0);
            INFO(to_string(m) << (seed ? " seed" : ""));
            CHECK(r.max_abs_energy_residual_w < 1e-6);
            if (!seed) {
                // and the reported heat rates add up to the storage
                const auto& f = r.final;
                CHECK(f.storage_w == Approx(f.metabolic_w + f.convection_w + f.radiation_w + f.evaporation_w + f.respiration_w).margin(1e-6));
            }
        }
}

TEST_CASE("Thermoregulation: the corrected vapour concentration changes the coupled model, not the temperature-only one", "[physics][thermoreg]") {
    const auto seed = run(ConvectionModel::coupled, true);
    const auto fixed = run(ConvectionModel::coupled, false);
    // The code's C is ~0.53 of the physical one; with the physical C the plume is not stagnant.
    CHECK(fixed.final.core_temp_c < seed.final.core_temp_c - 0.3);
    CHECK(fixed.final.mean_buoyancy_drive_c > 1.0);
    CHECK(run(ConvectionModel::dt_only, false).final.core_temp_c == Approx(run(ConvectionModel::dt_only, true).final.core_temp_c).margin(1e-9));
}

TEST_CASE("Fig. S23A (seed-compatible): at 0.1 m/s and above the coupled model converges toward temperature-only", "[physics][thermoreg]") {
    const double gap_still = run(ConvectionModel::coupled, true).final.core_temp_c - run(ConvectionModel::dt_only, true).final.core_temp_c;
    const double gap_fast = run(ConvectionModel::coupled, true, 55.0, 0.3).final.core_temp_c -
                            run(ConvectionModel::dt_only, true, 55.0, 0.3).final.core_temp_c;
    CHECK(gap_fast < 0.5 * gap_still);
    // S23B: a 1-min square wave keeps more of the gap than a constant speed of the same peak
    const double gap_wave = run(ConvectionModel::coupled, true, 55.0, 0.3, 60.0).final.core_temp_c -
                            run(ConvectionModel::dt_only, true, 55.0, 0.3, 60.0).final.core_temp_c;
    CHECK(gap_wave > gap_fast);
}

TEST_CASE("Thermoregulation: the square wave is on for the first half of each period", "[physics][thermoreg]") {
    AirSpeedSchedule s{0.2, 60.0};
    CHECK(s.at(0.0) == 0.2);
    CHECK(s.at(29.0) == 0.2);
    CHECK(s.at(30.0) == 0.0);
    CHECK(s.at(61.0) == 0.2);
    CHECK(AirSpeedSchedule{0.1, 0.0}.at(1234.0) == 0.1);
}

TEST_CASE("Thermoregulation: bad inputs and unstable steps are refused by name", "[physics][thermoreg]") {
    Exposure e;
    e.rh_pct = 120.0;
    CHECK_THROWS_WITH(validate(e), Catch::Contains("relative humidity"));
    e = Exposure{};
    e.air_speed.speed_m_s = -0.1;
    CHECK_THROWS_WITH(validate(e), Catch::Contains("air speed"));
    e = Exposure{};
    e.time_step_s = 10.0;
    CHECK_THROWS_WITH(validate(e), Catch::Contains("time step"));
    e = Exposure{};
    e.duration_s = 0.0;
    CHECK_THROWS_WITH(validate(e), Catch::Contains("duration"));
    e = Exposure{};
    e.output_interval_s = 1.5;
    e.time_step_s = 1.0;
    CHECK_THROWS_AS(validate(e), std::domain_error);
    CHECK_NOTHROW(validate(Exposure{}));
}

TEST_CASE("Seed-compatible mode reproduces the published code's own output (GNU Octave run, every minute)", "[physics][thermoreg]") {
    std::ifstream in(std::string(MANIKIND_TEST_DATA_DIR) + "/thermoreg/octave_fig4c.csv");
    REQUIRE(in.good());
    std::string line;
    std::getline(in, line);
    const auto r = run(ConvectionModel::coupled, true);
    int rows = 0;
    while (std::getline(in, line)) {
        std::stringstream ss(line);
        std::vector<double> v;
        for (std::string cell; std::getline(ss, cell, ',');) v.push_back(std::stod(cell));
        REQUIRE(v.size() == 8);
        const auto& s = at_minute(r, v[0] / 60.0);
        INFO("t = " << v[0] << " s");
        // Octave's columns: core, mean skin, latent, conv, rad (losses), storage, 50 x drive.
        CHECK(s.core_temp_c == Approx(v[1]).margin(1e-6));
        CHECK(s.mean_skin_temp_c == Approx(v[2]).margin(1e-6));
        CHECK(s.evaporation_w == Approx(-v[3]).margin(1e-5));
        CHECK(s.convection_w == Approx(-v[4]).margin(1e-5));
        CHECK(s.radiation_w == Approx(-v[5]).margin(1e-5));
        CHECK(s.storage_w == Approx(v[6]).margin(1e-5));
        CHECK(s.mean_buoyancy_drive_c == Approx(v[7] / 50.0).margin(1e-6));
        ++rows;
    }
    CHECK(rows == 121);
}

TEST_CASE("clothing: the default clo is the code's layout (0.26 clo area-weighted), 0 clo undresses it, and in 41 C "
          "heat the bare body gains more heat and ends warmer in its skin", "[physics][thermoreg]") {
    // 0.054 m²K/W on trunk, legs and feet, area-weighted over the six segments' areas, in clo.
    const double areas[] = {0.133, 0.680, 0.254, 0.095, 0.597, 0.130};
    const double r[] = {0.0, 0.054, 0.0, 0.0, 0.054, 0.054};
    double num = 0.0, den = 0.0;
    for (int i = 0; i < 6; ++i) num += areas[i] * r[i], den += areas[i];
    CHECK(num / den / 0.155 == Approx(default_clo).margin(0.005));
    Exposure e;  // Fig. 4: 41 C air, MRT 55 C
    ModelOptions dressed;
    ModelOptions same = dressed;
    same.clo = default_clo;
    CHECK(simulate(e, same).final.core_temp_c == simulate(e, dressed).final.core_temp_c);
    ModelOptions bare = dressed;
    bare.clo = 0.0;
    const auto d = simulate(e, dressed), b = simulate(e, bare);
    // Air and walls hotter than the skin: clothing shields, so undressed gains more dry heat.
    CHECK(b.final.convection_w + b.final.radiation_w > d.final.convection_w + d.final.radiation_w);
    CHECK(b.final.mean_skin_temp_c > d.final.mean_skin_temp_c);
    ModelOptions silly = dressed;
    silly.clo = -1.0;
    CHECK_THROWS_AS(simulate(e, silly), std::domain_error);
}

TEST_CASE("Body steps: fed back its own modelled losses as measured ones, the model runs as simulate() does, and "
          "the energy balance closes with measured losses", "[physics][thermoreg][loop]") {
    Exposure e;  // Fig. 4: 41 C, MRT 55 C, 20 %, 2 h
    ModelOptions o;
    const auto reference = simulate(e, o);
    Body body(e.met, o);
    const Environment env{e.air_temp_c, e.mrt_c, e.rh_pct, 0.0};
    for (int step = 0; step <= 7200; ++step) {
        Body probe = body;  // what the model alone would lose this step
        const SegmentValues loss = probe.step(1.0, env).modelled_loss_w;
        body.step(1.0, env, &loss);
    }
    const auto nodes = body.node_temps_c();
    for (int j = 0; j < node_count; ++j) CHECK(nodes[static_cast<std::size_t>(j)] == Approx(reference.final_node_temps_c[static_cast<std::size_t>(j)]).margin(1e-9));
    CHECK(body.max_abs_energy_residual_w() < 1e-6);
    // A different measured loss moves the body: 20 W more lost from the trunk cools the core.
    Body cooled(e.met, o);
    for (int step = 0; step < 1800; ++step) {
        Body probe = cooled;
        SegmentValues loss = probe.step(1.0, env).modelled_loss_w;
        loss[1] += 20.0;
        cooled.step(1.0, env, &loss);
    }
    Body plain(e.met, o);
    for (int step = 0; step < 1800; ++step) plain.step(1.0, env);
    // 20 W for 30 min is 36 kJ; the body's ~250 kJ/K would cool ~0.14 K if it all left the core.
    CHECK(cooled.node_temps_c()[4] < plain.node_temps_c()[4] - 0.03);
    CHECK(cooled.max_abs_energy_residual_w() < 1e-6);
    SegmentValues bad{};
    bad[2] = std::nan("");
    CHECK_THROWS_AS(cooled.step(1.0, env, &bad), std::domain_error);
}

TEST_CASE("Body restore: a model continued from its recorded node temperatures follows the uninterrupted run",
          "[physics][thermoreg][loop]") {
    ModelOptions o;
    o.clo = 0.0;
    const Environment env{41.0, 40.6, 20.0, 0.0};
    Body whole(1.5, o), first(1.5, o);
    for (int step = 0; step < 3600; ++step) whole.step(1.0, env), first.step(1.0, env);
    Body resumed(1.5, o);
    resumed.restore(first.time_s(), first.node_temps_c());
    for (int step = 0; step < 3600; ++step) whole.step(1.0, env), resumed.step(1.0, env);
    CHECK(resumed.time_s() == Approx(7200.0));
    for (int j = 0; j < node_count; ++j)
        CHECK(resumed.node_temps_c()[static_cast<std::size_t>(j)] == Approx(whole.node_temps_c()[static_cast<std::size_t>(j)]).margin(1e-9));
    std::array<double, node_count> hot{};
    hot.fill(37.0);
    hot[3] = 60.0;
    CHECK_THROWS_AS(resumed.restore(0.0, hot), std::domain_error);
}
