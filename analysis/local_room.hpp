// A trial's room where it is not uniform (issue 65): what each zone meets beside the probes'
// reading (its own air and radiant temperature, a jet, a seat, the sun), as the campaign states
// it per case ([[cases.local]], docs/comfort.md). Carried in the database's case conditions and in
// campaign.json's trials (`local`), read back into the twin's inputs by reconcile.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "analysis/zone_map.hpp"
#include "physics/twin/twin.hpp"

namespace manikind::analysis {

// One entry per zone of the map, in the map's order; empty: the room is uniform.
using LocalRoom = std::vector<physics::twin::LocalEnvironment>;

// The values a room entry may take, one table for [[simulation.local]] (daemon/config.cpp),
// [[cases.local]] (daemon/campaign_plan.cpp) and campaign.json's trials[].local (below).
struct LocalRange {
    const char* key;
    double lo, hi;
    const char* unit;
};
inline constexpr LocalRange kLocalRanges[] = {{"air_offset_c", -30.0, 30.0, "K"},
                                              {"radiant_offset_c", -60.0, 60.0, "K"},
                                              {"air_speed_m_s", 0.0, 10.0, "m/s"},
                                              {"contact_w_m2", -300.0, 300.0, "W/m²"},
                                              {"solar_w_m2", 0.0, 1000.0, "W/m²"}};
// The row of `key` (one of the five above); throws std::out_of_range for another.
const LocalRange& local_range(std::string_view key);

// One entry of [[simulation.local]] or [[cases.local]] laid on the zones it names (`zones`, indices
// into the room): offsets, contact and sun add up where entries meet; the last air speed named holds.
void add_to_room(LocalRoom& room, const std::vector<std::size_t>& zones, const physics::twin::LocalEnvironment& entry);

// `[{"zone": 3, "air_offset_c": 1.5, ...}]`: the zones that are not uniform only, by zone id, each
// key present only where it is not the uniform room's (docs/formats.md, trials[].local).
nlohmann::json local_room_json(const ZoneMap& map, const LocalRoom& room);

// The inverse, every value checked (a zone of the map, each number within the range the campaign
// file allows). On a problem: empty, and `why` names the entry and the key.
LocalRoom parse_local_room(const ZoneMap& map, const nlohmann::json& doc, std::string& why);

}  // namespace manikind::analysis
