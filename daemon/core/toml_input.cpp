#include "daemon/core/toml_input.hpp"

#include <fstream>
#include <sstream>

#include <fmt/core.h>

#include "daemon/core/user_error.hpp"

namespace manikind::toml_input {

toml::table parse(const std::string& text, const std::string& source_name) {
    try {
        return toml::parse(text, source_name);
    } catch (const toml::parse_error& e) {
        throw UserError(fmt::format("{}: {}", where(source_name, e.source()), e.description()));
    }
}

std::string where(const std::string& source_name, const toml::source_region& region) {
    return fmt::format("{}:{}:{}", source_name, region.begin.line, region.begin.column);
}

std::optional<std::string> read_file(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return std::nullopt;
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

}  // namespace manikind::toml_input
