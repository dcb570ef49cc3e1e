#pragma once
// The simulated lab's wardrobe (docs/clothing.md, "The simulated lab wears clothes"): typical
// ensembles by id, each garment a twin `clothing` term over one region with its intrinsic
// insulation, intrinsic evaporative resistance and clothing area factor. Values are of the order
// ISO 9920's tables give for such garments (its Annex tables of garment insulation: a coverall
// ~0.5-0.7 clo intrinsic, an insulated jacket and trousers ~1.0-1.5 clo); per region they are
// this project's choice, not copied from a table.
#include <optional>
#include <string>
#include <vector>

#include "physics/twin/twin.hpp"

namespace manikind::sim {

struct WardrobeEnsemble {
    std::string id;
    std::string description;
    double fcl = 1.0;
    std::vector<physics::twin::Term> garments;  // one `clothing` term per covered region
};

// The built-in ensembles: "coverall", "jacket", "tshirt-shorts". nullopt for any other id
// (the nude manikin is "nude": no garments).
std::optional<WardrobeEnsemble> wardrobe_ensemble(const std::string& id);
std::vector<std::string> wardrobe_ids();

}  // namespace manikind::sim
