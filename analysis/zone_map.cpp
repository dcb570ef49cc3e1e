#include "analysis/zone_map.hpp"

#include <charconv>
#include <set>
#include <sstream>

#include <fmt/core.h>

#include "analysis/input_error.hpp"

namespace manikind::analysis {

InputError::InputError(std::string file, std::size_t line, std::size_t column, std::string field,
                       const std::string& what)
    : std::runtime_error([&] {
          std::string where = file;
          if (line > 0) where += fmt::format(":{}", line);
          if (line > 0 && column > 0) where += fmt::format(":{}", column);
          if (!field.empty()) where += fmt::format(" (field '{}')", field);
          return where + ": " + what;
      }()),
      file_(std::move(file)), line_(line), column_(column), field_(std::move(field)) {}

double ZoneMap::total_area_m2() const {
    double sum = 0.0;
    for (const auto& z : zones) sum += z.area_m2;
    return sum;
}

std::vector<std::string> ZoneMap::regions() const {
    std::vector<std::string> out;
    for (const auto& z : zones) {
        bool seen = false;
        for (const auto& r : out) seen = seen || r == z.region;
        if (!seen) out.push_back(z.region);
    }
    return out;
}

std::vector<std::size_t> ZoneMap::zones_in(const std::string& region) const {
    std::vector<std::size_t> out;
    for (std::size_t i = 0; i < zones.size(); ++i)
        if (zones[i].region == region) out.push_back(i);
    return out;
}

const std::map<std::string, std::vector<std::string>>& default_model_segments() {
    static const std::map<std::string, std::vector<std::string>> map = {
        {"head", {"head"}},   {"trunk", {"chest", "back", "pelvis"}}, {"arms", {"upper_arm", "forearm"}},
        {"hands", {"hand"}},  {"legs", {"thigh", "calf"}},            {"feet", {"foot"}}};
    return map;
}

const ZoneMap& andi35_zone_map() {
    // Copied from config/andi35_zone_map.csv (ANDI, Thermetrics; Text S2); the test
    // "embedded andi35 map equals config/andi35_zone_map.csv" keeps the two identical.
    static const ZoneMap map{"andi35", {
        {1, "face", "head", "head", "c", 0.0571, 1.62, "front"},
        {2, "scalp", "head", "head", "c", 0.0622, 1.72, "up"},
        {3, "neck", "head", "head", "c", 0.0259, 1.50, "none"},
        {4, "upper_chest", "chest", "chest", "c", 0.0985, 1.33, "front"},
        {5, "abdomen", "chest", "chest", "c", 0.0882, 1.13, "front"},
        {6, "upper_back", "back", "back", "c", 0.1146, 1.35, "back"},
        {7, "lower_back", "back", "back", "c", 0.0882, 1.12, "back"},
        {8, "pelvis_front", "pelvis", "pelvis", "c", 0.0726, 0.95, "front"},
        {9, "buttock_l", "pelvis", "pelvis", "l", 0.0571, 0.92, "back"},
        {10, "buttock_r", "pelvis", "pelvis", "r", 0.0571, 0.92, "back"},
        {11, "shoulder_l", "upper_arm_l", "upper_arm", "l", 0.0207, 1.42, "up"},
        {12, "upper_arm_front_l", "upper_arm_l", "upper_arm", "l", 0.0311, 1.28, "front"},
        {13, "upper_arm_back_l", "upper_arm_l", "upper_arm", "l", 0.0311, 1.28, "back"},
        {14, "shoulder_r", "upper_arm_r", "upper_arm", "r", 0.0207, 1.42, "up"},
        {15, "upper_arm_front_r", "upper_arm_r", "upper_arm", "r", 0.0311, 1.28, "front"},
        {16, "upper_arm_back_r", "upper_arm_r", "upper_arm", "r", 0.0311, 1.28, "back"},
        {17, "forearm_front_l", "forearm_l", "forearm", "l", 0.0290, 1.02, "front"},
        {18, "forearm_back_l", "forearm_l", "forearm", "l", 0.0290, 1.02, "back"},
        {19, "forearm_front_r", "forearm_r", "forearm", "r", 0.0290, 1.02, "front"},
        {20, "forearm_back_r", "forearm_r", "forearm", "r", 0.0290, 1.02, "back"},
        {21, "hand_l", "hand_l", "hand", "l", 0.0477, 0.82, "none"},
        {22, "hand_r", "hand_r", "hand", "r", 0.0477, 0.82, "none"},
        {23, "thigh_front_l", "thigh_l", "thigh", "l", 0.0934, 0.70, "front"},
        {24, "thigh_back_l", "thigh_l", "thigh", "l", 0.0882, 0.70, "back"},
        {25, "thigh_front_r", "thigh_r", "thigh", "r", 0.0934, 0.70, "front"},
        {26, "thigh_back_r", "thigh_r", "thigh", "r", 0.0882, 0.70, "back"},
        {27, "calf_front_l", "calf_l", "calf", "l", 0.0622, 0.32, "front"},
        {28, "calf_back_l", "calf_l", "calf", "l", 0.0643, 0.32, "back"},
        {29, "calf_front_r", "calf_r", "calf", "r", 0.0622, 0.32, "front"},
        {30, "calf_back_r", "calf_r", "calf", "r", 0.0643, 0.32, "back"},
        {31, "foot_top_l", "foot_l", "foot", "l", 0.0363, 0.05, "front"},
        {32, "foot_sole_l", "foot_l", "foot", "l", 0.0259, 0.01, "down"},
        {33, "foot_top_r", "foot_r", "foot", "r", 0.0363, 0.05, "front"},
        {34, "foot_sole_r", "foot_r", "foot", "r", 0.0259, 0.01, "down"},
        {35, "crotch", "pelvis", "pelvis", "c", 0.0207, 0.85, "down"},
    }};
    return map;
}

std::vector<std::size_t> ZoneMap::zones_named(const std::string& part) const {
    std::vector<std::size_t> out;
    for (std::size_t i = 0; i < zones.size(); ++i)
        if (zones[i].name == part || zones[i].region == part || zones[i].segment == part) out.push_back(i);
    return out;
}

bool valid_facing(const std::string& facing) {
    return facing.empty() || facing == "front" || facing == "back" || facing == "up" || facing == "down" || facing == "none";
}

std::string validate_zone_map(const ZoneMap& map) {
    if (map.zones.empty()) return "the zone map has no zones";
    std::set<std::string> names;
    for (std::size_t i = 0; i < map.zones.size(); ++i) {
        const auto& z = map.zones[i];
        if (z.zone != static_cast<int>(i) + 1)
            return fmt::format("zone map entry {} has zone number {}, expected {} (zones are numbered 1..N in order)",
                               i + 1, z.zone, i + 1);
        if (z.zone > 99) return fmt::format("zone {}: at most 99 zones (column names are zNN)", z.zone);
        if (!(z.area_m2 > 0.0)) return fmt::format("zone {} ({}): area_m2 must be positive, found {}", z.zone, z.name, z.area_m2);
        if (z.region.empty()) return fmt::format("zone {}: empty region", z.zone);
        if (z.name.empty()) return fmt::format("zone {}: empty name", z.zone);
        if (!names.insert(z.name).second) return fmt::format("zone {}: duplicate name '{}'", z.zone, z.name);
    }
    return {};
}

ZoneMap parse_zone_map_csv(std::istream& in, const std::string& source_name) {
    // The facing column came with issue 61; maps written before it have seven columns.
    static const char* const kHeader7 = "zone,name,region,segment,side,area_m2,centroid_height_m";
    static const std::string kHeader = std::string(kHeader7) + ",facing";
    ZoneMap map;
    map.name = source_name;
    std::string line;
    std::size_t line_no = 0;
    if (!std::getline(in, line)) throw InputError(source_name, 1, 1, "", "empty file, expected a header row");
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line != kHeader && line != kHeader7)
        throw InputError(source_name, 1, 1, "", fmt::format("expected header '{}' (or without ',facing'), found '{}'", kHeader, line));
    const std::size_t n_fields = line == kHeader ? 8 : 7;
    static const char* const kFields[] = {"zone", "name", "region", "segment", "side", "area_m2", "centroid_height_m", "facing"};
    while (std::getline(in, line)) {
        ++line_no;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.empty()) continue;
        std::vector<std::string> cells;
        std::vector<std::size_t> starts;
        std::size_t start = 0;
        for (;;) {
            const auto comma = line.find(',', start);
            starts.push_back(start + 1);
            cells.push_back(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
            if (comma == std::string::npos) break;
            start = comma + 1;
        }
        if (cells.size() != n_fields)
            throw InputError(source_name, line_no, 1, "", fmt::format("expected {} fields, found {}", n_fields, cells.size()));
        auto number = [&](std::size_t i) {
            double v = 0.0;
            const auto& c = cells[i];
            const auto [p, ec] = std::from_chars(c.data(), c.data() + c.size(), v);
            if (ec != std::errc() || p != c.data() + c.size() || c.empty())
                throw InputError(source_name, line_no, starts[i], kFields[i],
                                 fmt::format("expected a number, found '{}'", c));
            return v;
        };
        Zone z;
        const double zone_number = number(0);
        z.zone = static_cast<int>(zone_number);
        if (static_cast<double>(z.zone) != zone_number)
            throw InputError(source_name, line_no, starts[0], "zone", fmt::format("expected an integer, found '{}'", cells[0]));
        z.name = cells[1];
        z.region = cells[2];
        z.segment = cells[3];
        z.side = cells[4];
        z.area_m2 = number(5);
        z.centroid_height_m = number(6);
        if (n_fields == 8) {
            z.facing = cells[7];
            if (!valid_facing(z.facing))
                throw InputError(source_name, line_no, starts[7], "facing",
                                 fmt::format("expected front, back, up, down or none, found '{}'", z.facing));
        }
        map.zones.push_back(std::move(z));
    }
    if (auto problem = validate_zone_map(map); !problem.empty()) throw InputError(source_name, 0, 0, "", problem);
    return map;
}

}  // namespace manikind::analysis
