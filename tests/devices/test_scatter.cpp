// Replicate-to-replicate scatter, as sweating-manikin labs see it, in the campaign generator
// and in the simulated lab's world: the spreads come out of the data at the configured size,
// the physics follows the actual enclosure, the recordings carry the probes' errors.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "analysis/zone_map.hpp"
#include "daemon/acquisition.hpp"
#include "daemon/config.hpp"
#include "base/user_error.hpp"
#include "physics/twin/twin.hpp"
#include "sim/campaign/campaign_generator.hpp"
#include "sim/world/world.hpp"

using namespace manikind;

namespace {

std::vector<sim::ZoneSpec> andi35_zones() {
    std::vector<sim::ZoneSpec> zones;
    for (const auto& z : analysis::andi35_zone_map().zones) zones.push_back({{z.zone, z.segment, z.region, z.area_m2, 35.0}, z.name});
    return zones;
}

sim::CampaignCase table_s3_case(int id) {
    for (const auto& c : sim::table_s3_cases())
        if (c.case_id == id) return c;
    FAIL("no Table S3 case " << id);
    return {};
}

double mean(const std::vector<double>& v, std::size_t from = 0) {
    return std::accumulate(v.begin() + static_cast<std::ptrdiff_t>(from), v.end(), 0.0) / static_cast<double>(v.size() - from);
}

double sample_sd(const std::vector<double>& v) {
    const double m = mean(v);
    double ss = 0.0;
    for (double x : v) ss += (x - m) * (x - m);
    return std::sqrt(ss / static_cast<double>(v.size() - 1));
}

// First sample of the last 30 min (the steady window the analysis uses).
std::size_t steady_from(const sim::GeneratedTrial& t) {
    const double from_s = t.t_s.back() - 1800.0;
    return static_cast<std::size_t>(std::lower_bound(t.t_s.begin(), t.t_s.end(), from_s) - t.t_s.begin());
}

// Between-replicate sd of each zone's steady mean flux, relative to the zone's mean over the
// replicates, pooled over zones (variances averaged). Zones whose flux is near zero carry no
// relative information and are skipped; `zones_used` says how many counted.
double pooled_relative_sd(const std::vector<sim::GeneratedTrial>& trials, std::size_t& zones_used) {
    const std::size_t n_zones = trials.front().heat_flux_w_m2.size();
    double var_sum = 0.0;
    zones_used = 0;
    for (std::size_t z = 0; z < n_zones; ++z) {
        std::vector<double> steady;
        for (const auto& t : trials) steady.push_back(mean(t.heat_flux_w_m2[z], steady_from(t)));
        const double m = mean(steady);
        if (std::abs(m) < 20.0) continue;
        const double sd = sample_sd(steady) / std::abs(m);
        var_sum += sd * sd;
        ++zones_used;
    }
    return zones_used ? std::sqrt(var_sum / static_cast<double>(zones_used)) : 0.0;
}

// Pooled between-replicate sd of the steady zone fluxes, W/m².
double pooled_absolute_sd(const std::vector<sim::GeneratedTrial>& trials) {
    const std::size_t n_zones = trials.front().heat_flux_w_m2.size();
    double var_sum = 0.0;
    for (std::size_t z = 0; z < n_zones; ++z) {
        std::vector<double> steady;
        for (const auto& t : trials) steady.push_back(mean(t.heat_flux_w_m2[z], steady_from(t)));
        const double sd = sample_sd(steady);
        var_sum += sd * sd;
    }
    return std::sqrt(var_sum / static_cast<double>(n_zones));
}

}  // namespace

TEST_CASE("generator: replicates of a case scatter in zone flux by the configured relative sd", "[devices][scatter]") {
    // Case 9 (39.6 °C, 38 % RH, wet): large evaporative fluxes, so the relative part dominates
    // the sensor noise of a 30-min mean (1.5 W/m² / sqrt(361) = 0.08 W/m²).
    sim::GeneratorOptions g;
    g.replicates = 20;
    g.seed = 7;
    g.scatter = sim::ReplicateScatter::none();
    for (const double rel_sd : {0.015, 0.04}) {
        g.scatter.replicate_flux_rel_sd = rel_sd;
        const auto trials = sim::generate_campaign({table_s3_case(9)}, andi35_zones(), g);
        REQUIRE(trials.size() == 20);
        std::size_t zones_used = 0;
        const double measured = pooled_relative_sd(trials, zones_used);
        REQUIRE(zones_used >= 20);
        // ~19 degrees of freedom per zone, >= 20 zones: the pooled sd is within a few % of the
        // truth (1/sqrt(2 * 380) = 3.6 % at 1 sigma); 15 % is over 4 sigma.
        INFO("configured " << rel_sd << ", measured " << measured << " over " << zones_used << " zones");
        CHECK(measured == Approx(rel_sd).epsilon(0.15));
    }
}

TEST_CASE("generator: the flux follows the actual enclosure, the recorded channels carry the probe error",
          "[devices][scatter]") {
    sim::GeneratorOptions g;
    g.replicates = 40;
    g.seed = 3;
    g.world.terms.push_back(sim::parse_effect("humidity_buoyancy:gamma=146"));
    const auto zones = andi35_zones();
    const auto c = table_s3_case(12);
    const auto trials = sim::generate_campaign({c}, zones, g);
    std::vector<double> air_error_c, rh_error_pct, wall_error_c, actual_air_c;
    for (const auto& t : trials) {
        INFO(t.id);
        const std::size_t from = steady_from(t);
        // Recorded minus actual: the probe's per-trial error, to within sensor noise over 901
        // samples and the 0.01 °C / 0.1 % resolution.
        const double recorded_air_error_c = mean(t.air_temp_c) - t.truth.air_temp_c;
        const double recorded_rh_error_pct = mean(t.air_rh_pct) - t.truth.air_rh_pct;
        const double recorded_wall_error_c = mean(t.wall_temp_c) - t.truth.wall_temp_c;
        CHECK(recorded_air_error_c == Approx(t.truth.probe_air_error_c).margin(0.006));
        CHECK(recorded_rh_error_pct == Approx(t.truth.probe_rh_error_pct).margin(0.05));
        CHECK(recorded_wall_error_c == Approx(t.truth.probe_wall_error_c).margin(0.006));
        air_error_c.push_back(recorded_air_error_c);
        rh_error_pct.push_back(recorded_rh_error_pct);
        wall_error_c.push_back(recorded_wall_error_c);
        actual_air_c.push_back(t.truth.air_temp_c);

        // The world's physics at the ACTUAL conditions, scaled and offset by this trial's draw,
        // is what the zones record once steady (noise of a 30-min mean: 0.08 W/m²).
        physics::twin::TrialConditions cond;
        cond.air_temp_c = t.truth.air_temp_c;
        cond.air_rh_pct = t.truth.air_rh_pct;
        cond.wall_temp_c = t.truth.wall_temp_c;
        cond.air_speed_m_s = g.air_speed_mean_m_s;
        cond.wettedness = c.wettedness;
        for (const auto& z : zones) {
            cond.zones.push_back(z.zone);
            cond.zones.back().skin_temp_c = c.skin_setpoint_c;
        }
        const auto fluxes = physics::twin::predict(g.world, cond);
        for (std::size_t z = 0; z < zones.size(); ++z) {
            const double expected_w_m2 = fluxes[z].q_total_w_m2 * t.truth.zone_flux_factor[z] + t.truth.zone_flux_offset_w_m2[z];
            CHECK(mean(t.heat_flux_w_m2[z], from) == Approx(expected_w_m2).margin(0.45));
        }
    }
    // Across trials the recorded-minus-actual spreads are the configured probe errors, and the
    // actual air scatters about the case's nominal by the setpoint error (40 trials: ~11 % at 1 sigma).
    CHECK(sample_sd(air_error_c) == Approx(g.scatter.probe_air_sd_c).epsilon(0.4));
    CHECK(sample_sd(rh_error_pct) == Approx(g.scatter.probe_rh_sd_pct).epsilon(0.4));
    CHECK(sample_sd(wall_error_c) == Approx(g.scatter.probe_wall_sd_c).epsilon(0.4));
    CHECK(sample_sd(actual_air_c) == Approx(g.scatter.replicate_air_sd_c).epsilon(0.4));
    CHECK(mean(actual_air_c) == Approx(c.air_temp_c).margin(4.0 * g.scatter.replicate_air_sd_c / std::sqrt(40.0)));
}

TEST_CASE("generator: without scatter replicates differ by sensor noise only, with the same noise draws",
          "[devices][scatter]") {
    sim::GeneratorOptions g;
    g.replicates = 6;
    g.seed = 21;
    g.scatter = sim::ReplicateScatter::none();
    const auto zones = andi35_zones();
    const auto exact = sim::generate_campaign({table_s3_case(9)}, zones, g);
    for (const auto& t : exact) {
        CHECK(t.truth.air_temp_c == t.conditions.air_temp_c);
        CHECK(t.truth.probe_air_error_c == 0.0);
        CHECK(std::all_of(t.truth.zone_flux_factor.begin(), t.truth.zone_flux_factor.end(), [](double f) { return f == 1.0; }));
    }
    // A 30-min mean of 361 samples with 1.5 W/m² noise scatters by 0.079 W/m² between replicates.
    const double noise_of_mean_w_m2 = g.flux_noise_w_m2 / std::sqrt(361.0);
    const double exact_sd = pooled_absolute_sd(exact);
    CHECK(exact_sd > 0.5 * noise_of_mean_w_m2);   // not copies: the sensors still add noise
    CHECK(exact_sd < 1.5 * noise_of_mean_w_m2);
    // Recorded air agrees between replicates to the noise of a 901-sample mean.
    for (const auto& t : exact) CHECK(mean(t.air_temp_c) == Approx(mean(exact.front().air_temp_c)).margin(0.006));

    // The default scatter on the same seed: the replicates now spread far beyond the noise.
    g.scatter = sim::ReplicateScatter{};
    const auto scattered = sim::generate_campaign({table_s3_case(9)}, zones, g);
    CHECK(pooled_absolute_sd(scattered) > 10.0 * exact_sd);
}

TEST_CASE("generator: a probe's calibration error shifts every trial's recording by the same amount, and the flux "
          "calibration scales and offsets the recorded flux - the physics is unchanged", "[devices][scatter]") {
    sim::GeneratorOptions g;
    g.replicates = 2;
    g.seed = 22;
    const auto zones = andi35_zones();
    const auto exact = sim::generate_campaign({table_s3_case(9)}, zones, g);
    g.probe_air_bias_c = 0.15;
    g.probe_rh_bias_pct = -1.2;
    g.probe_wall_bias_c = 0.4;
    g.flux_calibration_gain = 0.02;
    g.flux_calibration_offset_w_m2 = 0.5;
    const auto biased = sim::generate_campaign({table_s3_case(9)}, zones, g);
    REQUIRE(biased.size() == exact.size());
    for (std::size_t t = 0; t < exact.size(); ++t) {
        // Same draws, same actual enclosure: only the recordings move.
        CHECK(biased[t].truth.air_temp_c == exact[t].truth.air_temp_c);
        CHECK(mean(biased[t].air_temp_c) - mean(exact[t].air_temp_c) == Approx(0.15).margin(0.002));
        CHECK(mean(biased[t].air_rh_pct) - mean(exact[t].air_rh_pct) == Approx(-1.2).margin(0.02));
        CHECK(mean(biased[t].wall_temp_c) - mean(exact[t].wall_temp_c) == Approx(0.4).margin(0.002));
        const double q0 = mean(exact[t].heat_flux_w_m2[3]), q1 = mean(biased[t].heat_flux_w_m2[3]);
        CHECK(q1 == Approx(1.02 * q0 + 0.5).margin(0.02));
    }
    g.flux_calibration_gain = 0.7;
    CHECK_THROWS_WITH(sim::generate_campaign({table_s3_case(9)}, zones, g), Catch::Contains("gain"));
}

TEST_CASE("generator: a lab that trims its chamber by its own probes records the case's values, off in truth",
          "[devices][scatter]") {
    sim::GeneratorOptions g;
    g.replicates = 2;
    g.seed = 23;
    const auto zones = andi35_zones();
    g.probe_air_bias_c = 0.15;
    g.probe_rh_bias_pct = -1.2;
    const auto by_nominal = sim::generate_campaign({table_s3_case(5)}, zones, g);
    g.chamber_set_by_probes = true;
    const auto by_probes = sim::generate_campaign({table_s3_case(5)}, zones, g);
    REQUIRE(by_probes.size() == by_nominal.size());
    for (std::size_t t = 0; t < by_probes.size(); ++t) {
        // The same draws: the enclosure really settles off by the probes' errors, the recordings
        // land where the other lab's truth is (the case's values plus the trial's scatter).
        CHECK(by_probes[t].truth.air_temp_c == Approx(by_nominal[t].truth.air_temp_c - 0.15).margin(1e-12));
        CHECK(by_probes[t].truth.air_rh_pct == Approx(by_nominal[t].truth.air_rh_pct + 1.2).margin(1e-12));
        CHECK(mean(by_probes[t].air_temp_c) - mean(by_nominal[t].air_temp_c) == Approx(-0.15).margin(0.002));
        // The manikin feels the real air: case 5's skin sits at 35.0 °C, the air 0.15 °C nearer it.
        CHECK(mean(by_probes[t].heat_flux_w_m2[3]) != Approx(mean(by_nominal[t].heat_flux_w_m2[3])).margin(0.01));
    }
}

TEST_CASE("generator: negative or absurd spreads are refused by name", "[devices][scatter]") {
    sim::GeneratorOptions g;
    g.scatter.probe_rh_sd_pct = -0.1;
    CHECK_THROWS_WITH(sim::generate_campaign(sim::table_s3_cases(), andi35_zones(), g), Catch::Contains("probe_rh_sd_pct"));
    g.scatter = {};
    g.scatter.replicate_flux_rel_sd = 0.5;
    CHECK_THROWS_WITH(sim::generate_campaign(sim::table_s3_cases(), andi35_zones(), g), Catch::Contains("replicate_flux_rel_sd"));
}

namespace {

sim::WorldOptions world_options(std::uint64_t seed, const sim::ReplicateScatter& scatter) {
    sim::WorldOptions o;
    o.zones = andi35_zones();
    o.seed = seed;
    o.scatter = scatter;
    o.enclosure_table = sim::table_s3_cases();
    return o;
}

// One trial: the manikin starts and stops (the stop draws the next trial's scatter).
void run_trial(sim::World& w) {
    w.manikin_control(true);
    w.manikin_control(false);
}

}  // namespace

TEST_CASE("world: each trial draws new scatter, recorded minus actual is the probe error", "[devices][scatter]") {
    const sim::ReplicateScatter scatter;  // the defaults
    sim::World w(world_options(5, scatter));
    const int n_trials = 120, n_reads = 100;
    std::vector<double> air_error_c, rh_error_pct, wall_error_c, factors;
    for (int trial = 1; trial <= n_trials; ++trial) {
        REQUIRE(w.trial_scatter().trial == trial);
        double air_sum = 0.0, rh_sum = 0.0, wall_sum = 0.0;
        for (int i = 0; i < n_reads; ++i) {
            air_sum += w.measure_air_temp_c(1);
            rh_sum += w.measure_rh_pct(1);
            wall_sum += w.measure_wall_temp_c(1);
        }
        const double air_c = air_sum / n_reads - w.enclosure_air_temp_c();
        // Probe 1's error this trial, to within the noise of 100 reads (0.003 °C, 0.03 %, 0.005 °C).
        CHECK(air_c == Approx(w.trial_scatter().probe_air_error_c[0]).margin(0.015));
        air_error_c.push_back(air_c);
        rh_error_pct.push_back(rh_sum / n_reads - w.enclosure_rh_pct());
        wall_error_c.push_back(wall_sum / n_reads - w.wall_temp_c());
        for (double f : w.trial_scatter().zone_flux_factor) factors.push_back(f);
        run_trial(w);
    }
    // 120 trials: the sd estimates are within ~7 % at 1 sigma; 25 % is over 3 sigma.
    CHECK(sample_sd(air_error_c) == Approx(scatter.probe_air_sd_c).epsilon(0.25));
    CHECK(sample_sd(rh_error_pct) == Approx(scatter.probe_rh_sd_pct).epsilon(0.25));
    CHECK(sample_sd(wall_error_c) == Approx(scatter.probe_wall_sd_c).epsilon(0.25));
    CHECK(sample_sd(factors) == Approx(scatter.replicate_flux_rel_sd).epsilon(0.1));
    CHECK(mean(factors) == Approx(1.0).margin(0.002));
}

TEST_CASE("world: a zone's heat loss is the physics scaled by the trial's factor", "[devices][scatter]") {
    sim::ReplicateScatter flux_only = sim::ReplicateScatter::none();
    flux_only.replicate_flux_rel_sd = 0.015;
    sim::World exact(world_options(9, sim::ReplicateScatter::none()));
    sim::World scattered(world_options(9, flux_only));
    for (auto* w : {&exact, &scattered}) {
        w->set_chamber_setpoints(40.0, 19.0);
        w->step(1.0);  // one sub-step from the same state: only the factor differs
    }
    for (int z = 1; z <= exact.zone_count(); ++z) {
        const double factor = scattered.trial_scatter().zone_flux_factor[static_cast<std::size_t>(z - 1)];
        CHECK(factor != 1.0);
        CHECK(scattered.zone(z).loss_w_m2 == Approx(exact.zone(z).loss_w_m2 * factor).epsilon(1e-12));
    }
}

TEST_CASE("world: the enclosure settles at its nominal offset plus the trial's error", "[devices][scatter]") {
    sim::World w(world_options(13, sim::ReplicateScatter{}));
    w.set_chamber_setpoints(35.0, 27.0);  // Table S3 case 5: enclosure 35.3 °C, 35.6 %
    for (int i = 0; i < 40; ++i) w.step(600.0);  // 400 min: many time constants of the chain
    CHECK(w.enclosure_air_temp_c() == Approx(35.3 + w.trial_scatter().air_error_c).margin(1e-3));
    CHECK(w.enclosure_rh_pct() == Approx(35.6 + w.trial_scatter().rh_error_pct).margin(1e-3));
    CHECK(w.wall_temp_c() == Approx(w.enclosure_air_temp_c() - 0.4 + w.trial_scatter().wall_error_c).margin(1e-3));
}

TEST_CASE("world: the same seed gives the same scatter however often the devices were read", "[devices][scatter]") {
    sim::World a(world_options(77, sim::ReplicateScatter{}));
    sim::World b(world_options(77, sim::ReplicateScatter{}));
    for (int trial = 0; trial < 3; ++trial) {
        for (int i = 0; i < 10 * (trial + 1); ++i) a.measure_air_temp_c(2);  // b is never read
        run_trial(a);
        run_trial(b);
    }
    CHECK(a.trial_scatter().trial == 4);
    CHECK(a.trial_scatter().probe_air_error_c == b.trial_scatter().probe_air_error_c);
    CHECK(a.trial_scatter().zone_flux_factor == b.trial_scatter().zone_flux_factor);
    CHECK(a.trial_scatter().air_error_c == b.trial_scatter().air_error_c);
    sim::World other_seed(world_options(78, sim::ReplicateScatter{}));
    CHECK(other_seed.trial_scatter().zone_flux_factor != sim::World(world_options(77, sim::ReplicateScatter{})).trial_scatter().zone_flux_factor);
}

TEST_CASE("[simulation] scatter keys reach the simulated world, with range checks", "[devices][scatter][config]") {
    const auto c = config::parse_config("[simulation]\nreplicate_flux_rel_sd = 0.03\nprobe_air_sd_c = 0\nprobe_wall_sd_c = 0.2\n",
                                        "lab.toml");
    CHECK(c.warnings.empty());
    const auto o = simulated_lab_options(c);
    CHECK(o.world.scatter.replicate_flux_rel_sd == 0.03);
    CHECK(o.world.scatter.probe_air_sd_c == 0.0);
    CHECK(o.world.scatter.probe_wall_sd_c == 0.2);
    CHECK(o.world.scatter.probe_rh_sd_pct == sim::ReplicateScatter{}.probe_rh_sd_pct);  // the shipped default
    CHECK(config::default_config().simulation.scatter.replicate_flux_rel_sd == 0.015);
    CHECK_THROWS_WITH(config::parse_config("[simulation]\nprobe_rh_sd_pct = -1\n", "lab.toml"),
                      Catch::Contains("simulation.probe_rh_sd_pct"));
}
