#include "daemon/logging.hpp"

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "base/user_error.hpp"

namespace manikind {

void set_log_level(const std::string& level_name) {
    const auto level = spdlog::level::from_str(level_name);
    if (level == spdlog::level::off && level_name != "off")
        throw UserError(fmt::format("log level '{}': expected trace, debug, info, warn or error", level_name));
    spdlog::set_level(level);
}

}  // namespace manikind
