#include <catch2/catch.hpp>

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "physics/convection.hpp"
#include "physics/psychrometrics.hpp"
#include "physics/twin/twin.hpp"

using namespace manikind::physics::twin;

namespace {

// The shipped zone map (config/andi35_zone_map.csv) as twin inputs.
std::vector<ZoneInput> andi35_zones(double skin_temp_c) {
    std::ifstream in(std::string(MANIKIND_CONFIG_DIR) + "/andi35_zone_map.csv");
    std::string line;
    std::getline(in, line);
    std::vector<ZoneInput> zones;
    while (std::getline(in, line)) {
        std::stringstream ss(line);
        std::string zone, name, region, segment, side, area;
        std::getline(ss, zone, ',');
        std::getline(ss, name, ',');
        std::getline(ss, region, ',');
        std::getline(ss, segment, ',');
        std::getline(ss, side, ',');
        std::getline(ss, area, ',');
        zones.push_back({std::stoi(zone), segment, region, std::stod(area), skin_temp_c});
    }
    return zones;
}

// docs/twin-baseline.md written out by hand for one zone, independent of the implementation.
double baseline_by_hand(double a, double f, double ts, double ta, double tw, double rh, double w) {
    auto psat = [](double t_c) {
        const double t = t_c + 273.15;
        return std::exp(77.3450 + 0.0057 * t - 7235.0 / t) / std::pow(t, 8.2);
    };
    const double h = a * std::pow(std::abs(ts - ta), 0.25);
    const double q_conv = h * (ts - ta);
    const double q_rad = f * 0.98 * 5.670374e-8 * (std::pow(ts + 273.15, 4) - std::pow(tw + 273.15, 4));
    const double ps = psat(ts), pa = rh / 100.0 * psat(ta);
    const double q_evap = ps > pa ? w * 16.5 * h * (ps - pa) / 1000.0 : 0.0;
    return q_conv + q_rad + q_evap;
}

// One zone of `trial` alone in a uniform room at other temperatures, the air holding the trial's
// vapour pressure (its RH at the new temperature): what a zone meeting other inputs must equal.
ZoneFlux in_uniform_room(const TrialConditions& trial, const ZoneInput& zone, double air_c, double wall_c) {
    TrialConditions t = trial;
    const double p_pa = manikind::physics::vapour_pressure_pa(trial.air_temp_c, trial.air_rh_pct);
    t.air_temp_c = air_c;
    t.air_rh_pct = 100.0 * p_pa / manikind::physics::saturation_vapour_pressure_pa(air_c);
    t.wall_temp_c = wall_c;
    t.zones = {zone};
    return predict(TwinVersion{}, t).at(0);
}

}  // namespace

TEST_CASE("twin: baseline is docs/twin-baseline.md zone by zone (Table S3 case 9: 39.6 C, 38.3 %, wet)", "[physics][twin]") {
    TrialConditions trial;
    trial.air_temp_c = 39.6;
    trial.air_rh_pct = 38.3;
    trial.wettedness = 1.0;
    trial.zones = andi35_zones(35.0);
    REQUIRE(trial.zones.size() == 35);
    const auto fluxes = predict(TwinVersion{}, trial);
    REQUIRE(fluxes.size() == 35);
    for (std::size_t i = 0; i < fluxes.size(); ++i) {
        const auto seg = baseline_segment(trial.zones[i].segment);
        REQUIRE(seg.has_value());
        INFO("zone " << trial.zones[i].zone);
        CHECK(fluxes[i].q_total_w_m2 == Approx(baseline_by_hand(seg->wissler_a, seg->radiating_fraction, 35.0, 39.6, 39.6, 38.3, 1.0)));
    }
    // Whole body: the area-weighted mean of the zones; ANDI's area is 1.86 m2 (Text S2.2).
    std::vector<int> all;
    double area = 0.0;
    for (const auto& z : trial.zones) {
        all.push_back(z.zone);
        area += z.area_m2;
    }
    CHECK(area == Approx(1.86));
    const double wb = area_weighted_mean_w_m2(fluxes, trial.zones, all);
    CHECK(wb > 0.0);  // evaporation exceeds the convective gain from 39.6 C air
}

TEST_CASE("twin: dry skin in hot air gains heat (Table S3 case 3: 44.2 C, 34 C skin)", "[physics][twin]") {
    TrialConditions trial;
    trial.air_temp_c = 44.2;
    trial.air_rh_pct = 23.5;
    trial.wettedness = 0.0;
    trial.zones = andi35_zones(34.0);
    for (const auto& f : predict(TwinVersion{}, trial)) {
        CHECK(f.q_total_w_m2 < 0.0);
        CHECK(f.q_evaporation_w_m2 == 0.0);
    }
}

TEST_CASE("twin: humidity buoyancy with gamma = 146 and a floor h0 give Eq. 7 per zone", "[physics][twin]") {
    TrialConditions trial;
    trial.air_temp_c = 41.0;
    trial.air_rh_pct = 10.0;
    trial.wettedness = 1.0;
    trial.zones = {{1, "head", "head", 0.0571, 35.0}};
    TwinVersion v{"eq7", {{"humidity_buoyancy", {{"gamma", 146.0}}, "", {}}, {"diffusion_floor", {{"h0", 0.567}}, "", {}}}};
    const auto f = predict(v, trial).at(0);
    const double dc = 0.0341;  // C_sat(35) - C_air(41 C, 10 %), kg/m3 (manikin physics buoyancy)
    CHECK(f.h_c_w_m2k == Approx(0.567 + 2.6 * std::pow(std::abs(-6.0 + 146.0 * dc), 0.25)).epsilon(0.01));
    // Near stagnation the coupled h is far below the temperature-only one.
    CHECK(f.h_c_w_m2k < predict(TwinVersion{}, trial).at(0).h_c_w_m2k);
}

TEST_CASE("twin: each term moves the flux the way its physics says", "[physics][twin]") {
    TrialConditions trial;
    trial.air_temp_c = 39.6;
    trial.air_rh_pct = 38.3;
    trial.wettedness = 1.0;
    trial.air_speed_m_s = 0.1;
    trial.wall_temp_c = 39.0;
    trial.zones = {{5, "chest", "chest", 0.0882, 35.0}, {23, "thigh", "thigh_l", 0.0934, 35.0}};
    const auto base = predict(TwinVersion{}, trial);
    auto with = [&](Term t) { return predict(TwinVersion{"t", {t}}, trial); };
    CHECK(with({"mixed_convection", {{"scale", 1.0}}, "", {}})[0].h_c_w_m2k > base[0].h_c_w_m2k);
    CHECK(with({"wall_offset", {{"delta_c", 2.0}}, "", {}})[0].q_radiation_w_m2 < base[0].q_radiation_w_m2);
    CHECK(with({"air_temp_bias", {{"bias_c", 1.0}}, "", {}})[0].q_convection_w_m2 > base[0].q_convection_w_m2);
    const auto txt = with({"textile_resistance", {{"r_m2k_w", 0.0054}}, "", {}});  // Text S2.4
    CHECK(txt[0].surface_temp_c < 35.0);
    CHECK(txt[0].surface_temp_c == Approx(35.0 - 0.0054 * txt[0].q_total_w_m2).margin(1e-6));
    const auto pw = with({"partial_wettedness", {{"fraction", 0.3}}, "chest", {}});
    CHECK(pw[0].q_evaporation_w_m2 == Approx(0.3 * base[0].q_evaporation_w_m2));
    CHECK(pw[1].q_evaporation_w_m2 == Approx(base[1].q_evaporation_w_m2));  // other regions untouched
    const auto leak = with({"heat_leak", {{"q_w_m2", 12.0}}, "", {23}});
    CHECK(leak[1].q_total_w_m2 == Approx(base[1].q_total_w_m2 + 12.0));
    CHECK(leak[0].q_total_w_m2 == Approx(base[0].q_total_w_m2));
}

TEST_CASE("twin: unknown terms, parameters and segments are refused by name", "[physics][twin]") {
    TrialConditions trial;
    trial.zones = {{1, "head", "head", 0.05, 35.0}};
    CHECK_THROWS_WITH(predict(TwinVersion{"x", {{"warp_drive", {}, "", {}}}}, trial), Catch::Contains("warp_drive"));
    CHECK_THROWS_WITH(predict(TwinVersion{"x", {{"humidity_buoyancy", {{"g", 1.0}}, "", {}}}}, trial),
                      Catch::Contains("no parameter 'g'"));
    trial.zones[0].segment = "tail";
    CHECK_THROWS_AS(predict(TwinVersion{}, trial), std::invalid_argument);
}

TEST_CASE("twin: an input_pattern moves its input at each zone by value x the pattern's weight, as the baseline at "
          "those conditions would see it",
          "[twin][input_pattern]") {
    // Two zones: a face (front, 1.62 m) and an upper back (back, 1.35 m), wet, in warm humid air.
    TrialConditions trial;
    trial.air_temp_c = 36.0;
    trial.air_rh_pct = 50.0;
    trial.wall_temp_c = 35.5;
    trial.wettedness = 1.0;
    ZoneInput face{1, "head", "head", 0.0571, 35.0};
    face.height_m = 1.62;
    face.facing = 1;
    ZoneInput back{6, "back", "back", 0.1146, 35.0};
    back.height_m = 1.35;
    back.facing = -1;
    trial.zones = {face, back};
    auto one_zone_at = [&](const ZoneInput& z, double air_c, double wall_c) { return in_uniform_room(trial, z, air_c, wall_c).q_total_w_m2; };
    SECTION("air temperature by height, 2 K/m above the probe at 1.1 m") {
        Term t{"input_pattern", {{"value", 2.0}}, "", {}, "air_temp_c", "height"};
        const auto q = predict(TwinVersion{"v", {t}}, trial);
        CHECK(q[0].q_total_w_m2 == Approx(one_zone_at(face, 36.0 + 2.0 * (1.62 - 1.1), 35.5)).epsilon(1e-9));
        CHECK(q[1].q_total_w_m2 == Approx(one_zone_at(back, 36.0 + 2.0 * (1.35 - 1.1), 35.5)).epsilon(1e-9));
    }
    SECTION("the walls the front faces 3 K warmer: the back zone unchanged") {
        Term t{"input_pattern", {{"value", 3.0}}, "", {}, "wall_temp_c", "front"};
        const auto q = predict(TwinVersion{"v", {t}}, trial);
        const auto plain = predict(TwinVersion{}, trial);
        CHECK(q[0].q_total_w_m2 == Approx(one_zone_at(face, 36.0, 38.5)).epsilon(1e-9));
        CHECK(q[1].q_total_w_m2 == plain[1].q_total_w_m2);
        CHECK(q[0].q_total_w_m2 < plain[0].q_total_w_m2);  // warmer surroundings: less heat lost
    }
    SECTION("a height pattern on a zone without a height, or an unknown input, is refused") {
        TrialConditions no_height = trial;
        no_height.zones[0].height_m.reset();
        CHECK_THROWS_AS(predict(TwinVersion{"v", {Term{"input_pattern", {{"value", 1.0}}, "", {}, "air_temp_c", "height"}}}, no_height),
                        std::invalid_argument);
        CHECK_THROWS_AS(validate_term(Term{"input_pattern", {{"value", 1.0}}, "", {}, "air_speed", "height"}), std::invalid_argument);
    }
}

TEST_CASE("twin: a zone's local environment (a non-uniform room) is the room the zone meets: its own air, radiant "
          "temperature and jet, heat into a contact, sun absorbed, and none of it touches the other zones",
          "[twin][local]") {
    // A dry chest and back in a 24 °C room with walls at 23.6 °C: the chest meets what is set here.
    TrialConditions trial;
    trial.air_temp_c = 24.0;
    trial.air_rh_pct = 40.0;
    trial.wall_temp_c = 23.6;
    trial.air_speed_m_s = 0.05;
    ZoneInput chest{4, "chest", "chest", 0.0985, 34.0};
    ZoneInput back{6, "back", "back", 0.1146, 34.0};
    trial.zones = {chest, back};
    const auto plain = predict(TwinVersion{}, trial);
    auto with_local = [&](LocalEnvironment l) {
        TrialConditions t = trial;
        t.zones[0].local = l;
        const auto q = predict(TwinVersion{}, t);
        CHECK(q[1].q_total_w_m2 == plain[1].q_total_w_m2);  // the back is in the room as before
        return q[0];
    };
    // The same zone in a uniform room at other temperatures: what an offset must equal.
    auto in_room = [&](double air_c, double wall_c) { return in_uniform_room(trial, chest, air_c, wall_c); };
    CHECK(LocalEnvironment{}.uniform());
    SECTION("its own air and radiant temperature") {
        const auto f = with_local({-3.0, 8.0});
        const auto room = in_room(21.0, 31.6);
        CHECK(f.q_total_w_m2 == Approx(room.q_total_w_m2).epsilon(1e-12));
        CHECK(f.q_radiation_w_m2 < plain[0].q_radiation_w_m2);  // hot glass: less lost by radiation
        CHECK(f.q_convection_w_m2 > plain[0].q_convection_w_m2);  // cooler air: more by convection
    }
    SECTION("a jet: forced convection mixed with free (Eq. 9, de Dear's coefficient), the radiation as before") {
        LocalEnvironment jet;
        jet.air_speed_m_s = 0.6;
        const auto f = with_local(jet);
        const double h_free = plain[0].h_c_w_m2k;
        const double h_forced = manikind::physics::h_forced_de_dear_w_m2k(0.6);
        CHECK(f.h_c_w_m2k == Approx(std::cbrt(h_free * h_free * h_free + h_forced * h_forced * h_forced)).epsilon(1e-9));
        CHECK(f.q_radiation_w_m2 == plain[0].q_radiation_w_m2);
        CHECK(f.q_total_w_m2 > plain[0].q_total_w_m2 + 10.0);
    }
    SECTION("a contact draws heat and the sun gives it, beside the exchange with the room") {
        LocalEnvironment l;
        l.contact_w_m2 = 12.0;
        l.solar_w_m2 = 30.0;
        const auto f = with_local(l);
        CHECK(f.q_other_w_m2 == Approx(12.0 - 30.0));
        CHECK(f.q_total_w_m2 == Approx(plain[0].q_total_w_m2 - 18.0).epsilon(1e-12));
    }
}

TEST_CASE("twin: a version resolved once and only some zones predicted give predict's numbers exactly", "[physics][twin]") {
    // Reconcile's forward model resolves a version once for all trials, reuses one output and
    // computes only the zones a scoped term touches: every number must be predict's own, bit for bit.
    TrialConditions trial;
    trial.air_temp_c = 35.3;
    trial.air_rh_pct = 41.0;
    trial.wettedness = 1.0;
    trial.air_speed_m_s = 0.2;
    trial.wall_temp_c = 34.6;
    trial.zones = andi35_zones(35.0);
    for (std::size_t i = 0; i < trial.zones.size(); ++i) trial.zones[i].skin_temp_c = 34.2 + 0.05 * static_cast<double>(i);
    const TwinVersion v{"v", {{"humidity_buoyancy", {{"gamma", 146.0}}, "", {}},
                             {"textile_resistance", {{"r_m2k_w", 0.0054}}, "", {}},
                             {"partial_wettedness", {{"fraction", 0.4}}, "head", {}},
                             {"clothing", {{"icl_m2k_w", 0.1}, {"recl_m2kpa_w", 0.015}, {"fcl", 1.2}}, "chest", {}},
                             {"mixed_convection", {{"scale", 1.0}}, "", {}}}};
    const auto full = predict(v, trial);
    const ResolvedVersion resolved = resolve(v);
    std::vector<ZoneFlux> out;
    for (int round = 0; round < 2; ++round) {  // the second reuses the first's storage (and cached pressures)
        predict(resolved, trial, out);
        REQUIRE(out.size() == full.size());
        for (std::size_t i = 0; i < full.size(); ++i) {
            CHECK(out[i].q_total_w_m2 == full[i].q_total_w_m2);
            CHECK(out[i].surface_temp_c == full[i].surface_temp_c);
            CHECK(out[i].h_c_w_m2k == full[i].h_c_w_m2k);
        }
    }
    std::vector<char> only(trial.zones.size(), 0);
    std::vector<ZoneFlux> some(trial.zones.size());
    for (auto& f : some) f.q_total_w_m2 = -1.0;
    for (std::size_t i = 0; i < only.size(); i += 3) only[i] = 1;
    predict(resolved, trial, some, &only);
    for (std::size_t i = 0; i < full.size(); ++i)
        CHECK(some[i].q_total_w_m2 == (only[i] ? full[i].q_total_w_m2 : -1.0));
    // An unknown term is refused when resolved, as predict refuses it.
    CHECK_THROWS_AS(resolve(TwinVersion{"x", {{"warp_drive", {}, "", {}}}}), std::invalid_argument);
}
