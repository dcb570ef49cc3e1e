#pragma once
// Logging through spdlog: stderr for the CLI (stdout stays clean for --json), stderr plus a
// rotating file for the daemon.
#include <string>

namespace manikind {

// Sets the default logger's level from a config name (trace, debug, info, warn, error).
// Throws manikind::UserError for an unknown name.
void set_log_level(const std::string& level_name);

}  // namespace manikind
