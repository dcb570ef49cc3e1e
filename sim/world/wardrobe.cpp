#include "sim/world/wardrobe.hpp"

#include <map>

namespace manikind::sim {
namespace {

struct Cover {
    double icl_m2k_w, recl_m2kpa_w;
};

// Regions of the ANDI map (config/andi35_zone_map.csv), both sides where there are two.
const std::vector<std::string>& sided(const std::string& segment) {
    static const std::map<std::string, std::vector<std::string>> regions = {
        {"chest", {"chest"}},       {"back", {"back"}},         {"pelvis", {"pelvis"}},
        {"upper_arm", {"upper_arm_l", "upper_arm_r"}}, {"forearm", {"forearm_l", "forearm_r"}},
        {"hand", {"hand_l", "hand_r"}}, {"thigh", {"thigh_l", "thigh_r"}}, {"calf", {"calf_l", "calf_r"}},
        {"foot", {"foot_l", "foot_r"}}, {"head", {"head"}}};
    static const std::vector<std::string> none;
    const auto it = regions.find(segment);
    return it == regions.end() ? none : it->second;
}

WardrobeEnsemble make(const std::string& id, const std::string& description, double fcl,
                      const std::map<std::string, Cover>& by_segment) {
    WardrobeEnsemble e{id, description, fcl, {}};
    for (const auto& [segment, c] : by_segment)
        for (const auto& region : sided(segment))
            e.garments.push_back({"clothing", {{"icl_m2k_w", c.icl_m2k_w}, {"recl_m2kpa_w", c.recl_m2kpa_w}, {"fcl", fcl}}, region, {}});
    return e;
}

}  // namespace

std::optional<WardrobeEnsemble> wardrobe_ensemble(const std::string& id) {
    if (id == "coverall")
        return make(id, "cotton coverall over briefs and T-shirt, socks and shoes", 1.26,
                    {{"chest", {0.22, 0.030}}, {"back", {0.22, 0.030}}, {"pelvis", {0.26, 0.036}}, {"upper_arm", {0.16, 0.022}},
                     {"forearm", {0.14, 0.020}}, {"thigh", {0.17, 0.024}}, {"calf", {0.15, 0.022}}, {"foot", {0.20, 0.045}}});
    if (id == "jacket")
        return make(id, "insulated jacket and trousers over a base layer", 1.35,
                    {{"chest", {0.45, 0.070}}, {"back", {0.45, 0.070}}, {"pelvis", {0.40, 0.062}}, {"upper_arm", {0.38, 0.058}},
                     {"forearm", {0.34, 0.052}}, {"thigh", {0.30, 0.046}}, {"calf", {0.26, 0.040}}, {"foot", {0.25, 0.060}}});
    if (id == "tshirt-shorts")
        return make(id, "T-shirt and shorts, socks and trainers", 1.1,
                    {{"chest", {0.09, 0.012}}, {"back", {0.09, 0.012}}, {"pelvis", {0.12, 0.016}}, {"upper_arm", {0.06, 0.009}},
                     {"thigh", {0.05, 0.008}}, {"foot", {0.15, 0.030}}});
    return std::nullopt;
}

std::vector<std::string> wardrobe_ids() { return {"coverall", "jacket", "tshirt-shorts"}; }

}  // namespace manikind::sim
