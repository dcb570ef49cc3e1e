#pragma once
// Twin versions on disk: a TOML file per version, so results can say which physics they used.
//
//   name = "reconciled-2026-11-22"
//   based_on = "baseline"
//   [[terms]]
//   name = "humidity_buoyancy"
//   gamma = 146.0
//   [[terms]]
//   name = "partial_wettedness"
//   region = "head"
//   fraction = 0.3
#include <filesystem>
#include <string>

#include "physics/twin/twin.hpp"

namespace manikind::twin_store {

// "baseline" is built in; anything else is a path to a TOML file. Throws manikind::UserError
// naming file, line and key.
physics::twin::TwinVersion load_twin_version(const std::string& name_or_path);
physics::twin::TwinVersion parse_twin_version(const std::string& toml_text, const std::string& source_name);
std::string twin_version_to_toml(const physics::twin::TwinVersion& version, const std::string& based_on,
                                 const std::string& note);
void save_twin_version(const physics::twin::TwinVersion& version, const std::filesystem::path& path,
                       const std::string& based_on, const std::string& note);

}  // namespace manikind::twin_store
