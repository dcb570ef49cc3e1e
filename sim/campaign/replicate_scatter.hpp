#pragma once
// What makes one replicate of a sweating-manikin trial differ from the next in a real lab,
// drawn once per trial (all 1 sigma). Shared by the campaign generator and the simulated lab
// so both worlds scatter alike. The enclosure's ACTUAL conditions drive the physics; the
// RECORDED ones carry each probe's per-trial error on top.
#include <stdexcept>
#include <string>
#include <utility>

namespace manikind::sim {

struct ReplicateScatter {
    double replicate_flux_rel_sd = 0.015;   // zone flux x (1 + e): textile fit, sweat distribution (1.5 %)
    double replicate_flux_sd_w_m2 = 1.2;    // zone flux + offset: sensor placement, contact
    double replicate_air_sd_c = 0.08;       // enclosure air actually settles off its nominal value
    double replicate_rh_sd_pct = 0.6;       // ... and so does its humidity
    double replicate_wall_sd_c = 0.05;      // walls off their usual offset from the air
    double probe_air_sd_c = 0.05;           // recorded minus actual air temperature, constant in a trial
    double probe_rh_sd_pct = 0.5;           // recorded minus actual RH
    double probe_wall_sd_c = 0.1;           // recorded minus actual wall temperature

    // No scatter at all: replicates differ only by sensor noise (exact tests).
    static ReplicateScatter none() {
        return {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    }

    // Throws std::invalid_argument naming the first negative or non-finite spread.
    void validate() const {
        const std::pair<const char*, double> spreads[] = {
            {"replicate_flux_rel_sd", replicate_flux_rel_sd}, {"replicate_flux_sd_w_m2", replicate_flux_sd_w_m2},
            {"replicate_air_sd_c", replicate_air_sd_c},       {"replicate_rh_sd_pct", replicate_rh_sd_pct},
            {"replicate_wall_sd_c", replicate_wall_sd_c},     {"probe_air_sd_c", probe_air_sd_c},
            {"probe_rh_sd_pct", probe_rh_sd_pct},             {"probe_wall_sd_c", probe_wall_sd_c}};
        for (const auto& [name, sd] : spreads)
            if (!(sd >= 0.0 && sd < 1e6)) throw std::invalid_argument(std::string(name) + " must be a standard deviation >= 0");
        // Keeps 1 + e positive (5 sigma): scatter alone never reverses a zone's heat flow.
        if (replicate_flux_rel_sd > 0.2) throw std::invalid_argument("replicate_flux_rel_sd must be at most 0.2 (20 %)");
    }
};

}  // namespace manikind::sim
