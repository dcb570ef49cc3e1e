#include "daemon/simulated_lab.hpp"

#include <unistd.h>

#include <fmt/format.h>

#include "analysis/local_room.hpp"
#include "analysis/zone_map.hpp"
#include "base/user_error.hpp"
#include "drivers/register_map.hpp"

namespace manikind {

sim::SimLabOptions simulated_lab_options(const config::Config& config) {
    sim::SimLabOptions o;
    for (const auto& z : analysis::andi35_zone_map().zones)
        o.world.zones.push_back({{z.zone, z.segment, z.region, z.area_m2, 35.0}, z.name});
    o.world.physics.name = "simulated world";
    for (const auto& e : config.simulation.world_effects) {
        try {
            o.world.physics.terms.push_back(sim::parse_effect(e));
        } catch (const std::exception& ex) {
            throw UserError(fmt::format("simulation.world_effects: {}", ex.what()));
        }
    }
    // [[simulation.local]]: each entry names zones, regions or segments of the zone map; entries
    // add up where they meet, and the last air speed named for a zone holds.
    if (!config.simulation.local.empty()) {
        const auto& map = analysis::andi35_zone_map();
        o.world.local.assign(map.size(), {});
        for (std::size_t i = 0; i < config.simulation.local.size(); ++i) {
            const auto& e = config.simulation.local[i];
            for (const auto& name : e.zones) {
                const auto named = map.zones_named(name);
                physics::twin::LocalEnvironment entry{e.air_offset_c, e.radiant_offset_c, std::nullopt, e.contact_w_m2, e.solar_w_m2};
                if (e.air_speed_m_s >= 0.0) entry.air_speed_m_s = e.air_speed_m_s;
                analysis::add_to_room(o.world.local, named, entry);
                if (named.empty())
                    throw UserError(fmt::format("{}: simulation.local[{}].zones: '{}' is no zone, region or segment of the "
                                                "zone map (config/andi35_zone_map.csv: a zone as face, hand_l, thigh_back_r; "
                                                "a region as chest, upper_arm_l; a segment as thigh)",
                                                e.where, i, name));
            }
        }
    }
    o.world.seed = config.simulation.seed;
    o.world.scatter = config.simulation.scatter;
    o.manikin_period_s = config.simulation.manikin_period_s;
    o.world.air_speed_m_s = config.simulation.air_speed_m_s;
    o.world.wall_below_air_c = config.simulation.wall_below_air_c;
    o.world.enclosure_table = sim::table_s3_cases();
    o.world.watchdog_s = config.safety.watchdog_timeout_s;
    o.world.max_heater_power_w_m2 = config.devices.manikin_max_heater_power_w_m2;
    const auto convert = [](const RegisterMap& map) {
        std::vector<sim::RegisterDef> defs;
        for (const auto& r : map.registers) defs.push_back({r.spec, r.unit_id, r.probe});
        return defs;
    };
    o.chamber_registers = convert(register_map_from_setting(config.devices.chamber.register_map, "chamber", config.source_dir));
    o.datalogger_registers =
        convert(register_map_from_setting(config.devices.datalogger.register_map, "datalogger", config.source_dir));
    o.runtime_dir = config.simulation.runtime_dir.empty()
                        ? std::filesystem::temp_directory_path() / fmt::format("manikind-sim-{}", ::getpid())
                        : std::filesystem::path(config.simulation.runtime_dir);
    for (const auto& f : config.simulation.faults) {
        try {
            o.faults.push_back(sim::parse_fault(f));
        } catch (const std::exception& ex) {
            throw UserError(fmt::format("simulation.faults: {}", ex.what()));
        }
    }
    return o;
}

}  // namespace manikind
