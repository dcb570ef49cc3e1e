#pragma once
// A lab for the equivalent-temperature tests (issue 65), physics of its own, not the code under
// test's: per zone a still-air convective and radiative coefficient, a uniform calibration
// campaign, and a cabin whose zones each have their own air and radiant temperature, so each
// zone's true teq is known; one set of instrument errors per lab drawn within the specs
// campaign.json states, re-positioning scatter and reading noise. Used by tests/analysis/test_teq.cpp
// and tests/cli/test_cli_teq.cpp.
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "analysis/recording.hpp"
#include "analysis/zone_map.hpp"

namespace manikind::test::teq_lab {

// The manikin's true still-air coefficients, W/m²K: convection 2.5-4.5 and radiation 4.0-5.0 by
// zone (a fixed pattern, not from the code under test).
struct Manikin {
    analysis::ZoneMap map = analysis::andi35_zone_map();
    std::vector<double> hc, hr, skin_c;
    Manikin() {
        for (std::size_t z = 0; z < map.size(); ++z) {
            hc.push_back(2.5 + 2.0 * static_cast<double>((z * 7) % 11) / 10.0);
            hr.push_back(4.0 + 1.0 * static_cast<double>((z * 3) % 5) / 4.0);
            skin_c.push_back(34.0 + 0.1 * static_cast<double>(z % 4));
        }
    }
    double h(std::size_t z) const { return hc[z] + hr[z]; }
};

// The errors one lab's instruments carry for the whole of a calibration and a measurement (one
// manikin, one set of probes), drawn within the specs written to campaign.json.
struct LabErrors {
    double skin_c = 0.0, flux_offset_w_m2 = 0.0, flux_gain = 0.0, air_c = 0.0, wall_c = 0.0;
};

struct Noise {
    double q_trial_sd_w_m2 = 0.8;   // per trial and zone: re-positioning, lateral flows
    double q_row_sd_w_m2 = 0.5;     // per reading
    double skin_row_sd_c = 0.003;
    double probe_row_sd_c = 0.02;
};

inline std::map<std::string, analysis::InstrumentSpec> lab_specs() {
    auto s = analysis::default_instrument_specs();
    s["wall_temp_c"] = {0.15, 0.0, analysis::Distribution::rectangular};  // a calibrated surface probe
    return s;
}

inline LabErrors draw_lab(std::mt19937_64& rng) {
    const auto s = lab_specs();
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    LabErrors e;
    e.skin_c = u(rng) * s.at("skin_temp_c").accuracy;
    e.flux_offset_w_m2 = u(rng) * s.at("heat_flux_w_m2").accuracy;
    e.flux_gain = u(rng) * s.at("heat_flux_w_m2").accuracy_of_reading;
    e.air_c = u(rng) * s.at("air_temp_c").accuracy;
    e.wall_c = u(rng) * s.at("wall_temp_c").accuracy;
    return e;
}

// One steady trial (35 min at 15 s): the zones at their skin temperature, losing
// h_z (t_sk - teq_z) (the definition of teq), as the lab's instruments read it.
inline analysis::Trial make_trial(const Manikin& m, const std::string& id, int case_id, int replicate, double air_c, double wall_c,
                     double speed_m_s, const std::vector<double>& teq_true_c, const LabErrors& e, const Noise& n,
                     std::mt19937_64& rng) {
    analysis::Trial t;
    t.info.id = id;
    t.info.case_id = case_id;
    t.info.replicate = replicate;
    t.info.file = "trials/" + id + ".csv";
    std::normal_distribution<double> g(0.0, 1.0);
    const std::size_t rows = 141;
    for (std::size_t k = 0; k < rows; ++k) {
        t.data.t_s.push_back(15.0 * static_cast<double>(k));
        t.data.air_temp_c.push_back(air_c + e.air_c + n.probe_row_sd_c * g(rng));
        t.data.wall_temp_c.push_back(wall_c + e.wall_c + n.probe_row_sd_c * g(rng));
        t.data.air_rh_pct.push_back(40.0);
        t.data.air_speed_m_s.push_back(speed_m_s);
    }
    t.data.skin_temp_c.resize(m.map.size());
    t.data.heat_flux_w_m2.resize(m.map.size());
    for (std::size_t z = 0; z < m.map.size(); ++z) {
        const double q = m.h(z) * (m.skin_c[z] - teq_true_c[z]) + n.q_trial_sd_w_m2 * g(rng);
        for (std::size_t k = 0; k < rows; ++k) {
            t.data.skin_temp_c[z].push_back(m.skin_c[z] + e.skin_c + n.skin_row_sd_c * g(rng));
            t.data.heat_flux_w_m2[z].push_back(q * (1.0 + e.flux_gain) + e.flux_offset_w_m2 + n.q_row_sd_w_m2 * g(rng));
        }
    }
    return t;
}

inline analysis::Campaign empty_campaign(const Manikin& m, const std::string& name) {
    analysis::Campaign c;
    c.name = name;
    c.zone_map = m.map;
    c.instruments = lab_specs();
    return c;
}

// Uniform calibration: air = wall at 12, 18 and 24 °C, still air, two replicates each.
inline analysis::Campaign calibration_campaign(const Manikin& m, const LabErrors& e, const Noise& n, std::mt19937_64& rng,
                                  double wall_offset_case2_k = 0.0, double speed_case3_m_s = 0.05) {
    auto c = empty_campaign(m, "teq-cal");
    int case_id = 0;
    for (const double t : {12.0, 18.0, 24.0}) {
        ++case_id;
        const std::vector<double> uniform(m.map.size(), t);
        for (int r = 1; r <= 2; ++r)
            c.trials.push_back(make_trial(m, fmt::format("c{:02}-r{}", case_id, r), case_id, r, t,
                                          t + (case_id == 2 ? wall_offset_case2_k : 0.0), case_id == 3 ? speed_case3_m_s : 0.05,
                                          uniform, e, n, rng));
    }
    return c;
}

// A non-uniform cabin: air 23 °C and walls 19 °C on average, each zone with its own air and
// radiant temperature; teq_z = (hc ta_z + hr tr_z) / (hc + hr) in still air.
struct Cabin {
    std::vector<double> teq_c;
    analysis::Campaign campaign;
};
inline Cabin cabin_campaign(const Manikin& m, const LabErrors& e, const Noise& n, std::mt19937_64& rng, int replicates = 3) {
    Cabin out;
    std::uniform_real_distribution<double> da(-3.0, 3.0), dr(-6.0, 6.0);
    for (std::size_t z = 0; z < m.map.size(); ++z) {
        const double ta = 23.0 + da(rng), tr = 19.0 + dr(rng);
        out.teq_c.push_back((m.hc[z] * ta + m.hr[z] * tr) / m.h(z));
    }
    out.campaign = empty_campaign(m, "cabin");
    for (int r = 1; r <= replicates; ++r)
        out.campaign.trials.push_back(make_trial(m, fmt::format("c01-r{}", r), 1, r, 23.0, 19.0, 0.05, out.teq_c, e, n, rng));
    return out;
}

// Written as a recording folder and read back, as `manikin` would.
inline analysis::Campaign round_trip(const analysis::Campaign& c, const std::filesystem::path& folder) {
    analysis::write_campaign(folder, c);
    return analysis::read_campaign(folder);
}

// Whole body from the truth: the uniform temperature giving the same total loss.
inline double whole_body_truth(const Manikin& m, const std::vector<double>& teq_c) {
    double num = 0.0, den = 0.0;
    for (std::size_t z = 0; z < m.map.size(); ++z) {
        num += m.map.zones[z].area_m2 * m.h(z) * teq_c[z];
        den += m.map.zones[z].area_m2 * m.h(z);
    }
    return num / den;
}

}  // namespace manikind::test::teq_lab
