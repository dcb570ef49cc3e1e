#include "analysis/local_room.hpp"

#include <cmath>
#include <stdexcept>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace manikind::analysis {

const LocalRange& local_range(std::string_view key) {
    for (const auto& r : kLocalRanges)
        if (key == r.key) return r;
    throw std::out_of_range("no room entry key '" + std::string(key) + "'");
}

void add_to_room(LocalRoom& room, const std::vector<std::size_t>& zones, const physics::twin::LocalEnvironment& entry) {
    for (const std::size_t z : zones) {
        auto& l = room.at(z);
        l.air_offset_c += entry.air_offset_c;
        l.radiant_offset_c += entry.radiant_offset_c;
        if (entry.air_speed_m_s) l.air_speed_m_s = entry.air_speed_m_s;
        l.contact_w_m2 += entry.contact_w_m2;
        l.solar_w_m2 += entry.solar_w_m2;
    }
}

nlohmann::json local_room_json(const ZoneMap& map, const LocalRoom& room) {
    nlohmann::json out = nlohmann::json::array();
    for (std::size_t z = 0; z < room.size() && z < map.zones.size(); ++z) {
        const auto& l = room[z];
        if (l.uniform()) continue;
        nlohmann::json e = {{"zone", map.zones[z].zone}};
        if (l.air_offset_c != 0.0) e["air_offset_c"] = l.air_offset_c;
        if (l.radiant_offset_c != 0.0) e["radiant_offset_c"] = l.radiant_offset_c;
        if (l.air_speed_m_s) e["air_speed_m_s"] = *l.air_speed_m_s;
        if (l.contact_w_m2 != 0.0) e["contact_w_m2"] = l.contact_w_m2;
        if (l.solar_w_m2 != 0.0) e["solar_w_m2"] = l.solar_w_m2;
        out.push_back(std::move(e));
    }
    return out;
}

LocalRoom parse_local_room(const ZoneMap& map, const nlohmann::json& doc, std::string& why) {
    why.clear();
    if (!doc.is_array()) {
        why = "expected an array of objects, each with the zone (its id in the zone map) and what it meets there";
        return {};
    }
    LocalRoom room(map.zones.size());
    for (std::size_t i = 0; i < doc.size(); ++i) {
        const auto& e = doc[i];
        const std::string at = fmt::format("[{}]", i);
        if (!e.is_object() || !e.contains("zone") || !e.at("zone").is_number_integer()) {
            why = at + ".zone: expected the zone's id (an integer of the zone map)";
            return {};
        }
        const auto id = e.at("zone").get<std::int64_t>();
        std::size_t z = map.zones.size();
        for (std::size_t k = 0; k < map.zones.size(); ++k)
            if (map.zones[k].zone == id) z = k;
        if (z == map.zones.size()) {
            why = fmt::format("{}.zone: {} is no zone of the zone map", at, id);
            return {};
        }
        auto& l = room[z];
        for (const auto& [key, value] : e.items()) {
            if (key == "zone") continue;
            const LocalRange* r = nullptr;
            for (const auto& k : kLocalRanges)
                if (key == k.key) r = &k;
            if (!r) {
                why = fmt::format("{}.{}: unknown key (known: zone, air_offset_c, radiant_offset_c, air_speed_m_s, contact_w_m2, "
                                  "solar_w_m2)", at, key);
                return {};
            }
            if (!value.is_number() || !std::isfinite(value.get<double>()) || value.get<double>() < r->lo || value.get<double>() > r->hi) {
                why = fmt::format("{}.{}: expected a number within {}..{}, found {}", at, key, r->lo, r->hi, value.dump());
                return {};
            }
            const double v = value.get<double>();
            if (key == "air_offset_c") l.air_offset_c = v;
            else if (key == "radiant_offset_c") l.radiant_offset_c = v;
            else if (key == "air_speed_m_s") l.air_speed_m_s = v;
            else if (key == "contact_w_m2") l.contact_w_m2 = v;
            else l.solar_w_m2 = v;
        }
    }
    return room;
}

}  // namespace manikind::analysis
