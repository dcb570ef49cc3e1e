#pragma once
// The manikin's zone map: which zone is where, its area (the weight of area-weighted means)
// and the region it belongs to. The ANDI 35-zone map is compiled in, so `manikin` runs from
// any directory; config/andi35_zone_map.csv is the same table (a test holds them equal).
#include <istream>
#include <map>
#include <string>
#include <vector>

namespace manikind::analysis {

struct Zone {
    int zone = 0;                  // 1-based zone number (column prefix zNN in trial CSVs)
    std::string name;              // face, scalp, ...
    std::string region;            // head, chest, ..., upper_arm_l, ... (grouping for results)
    std::string segment;           // side-less body segment (upper_arm)
    std::string side;              // l, r, c
    double area_m2 = 0.0;
    double centroid_height_m = 0.0;
    // Which way the zone's surface faces: front, back, up, down, none (hands, neck); empty where
    // the map does not say (maps written before issue 61). Reconcile's front/back patterns use it.
    std::string facing{};
};

// front, back, up, down, none, or empty (not given).
bool valid_facing(const std::string& facing);

struct ZoneMap {
    std::string name;              // "andi35" or "inline"
    std::vector<Zone> zones;       // ordered by zone number, numbered 1..N without holes

    std::size_t size() const { return zones.size(); }
    double total_area_m2() const;
    // Regions in order of first appearance in the map (head, chest, back, pelvis, ...).
    std::vector<std::string> regions() const;
    // Indices into `zones` of the zones in `region`.
    std::vector<std::size_t> zones_in(const std::string& region) const;
    // Indices of the zones `part` names: a zone by its name, a region or a segment
    // ([[simulation.local]] entries); empty when it names none.
    std::vector<std::size_t> zones_named(const std::string& part) const;
};

// The ANDI 35-zone map (config/andi35_zone_map.csv), compiled in.
const ZoneMap& andi35_zone_map();

// Which zone-map segments make each of the thermoregulation model's six segments (head, trunk,
// arms, hands, legs, feet): the default of [physiological.segments] (docs/daemon.md), and what
// `manikin physio` spreads a zone's sensor error over.
const std::map<std::string, std::vector<std::string>>& default_model_segments();

// Parses the CSV form (header zone,name,region,segment,side,area_m2,centroid_height_m[,facing]).
// Throws InputError naming `source_name`, line and column.
ZoneMap parse_zone_map_csv(std::istream& in, const std::string& source_name);

// Checks a map is usable: zones numbered 1..N, positive areas, non-empty names and regions.
// Returns the first problem, or an empty string.
std::string validate_zone_map(const ZoneMap& map);

}  // namespace manikind::analysis
