#pragma once
// Shared input plumbing for the TOML files the daemon reads (config, twin versions, register
// maps): one place decides how a parse error and a node's position are reported
// ("file:line:column"), and how a file is read.
#include <filesystem>
#include <optional>
#include <string>

#include <toml++/toml.h>

namespace manikind::toml_input {

// Parses TOML text; a syntax error becomes a manikind::UserError "source:line:col: what".
toml::table parse(const std::string& text, const std::string& source_name);

// "source:line:column" of a node or region, for messages that name the key.
std::string where(const std::string& source_name, const toml::source_region& region);
inline std::string where(const std::string& source_name, const toml::node& node) {
    return where(source_name, node.source());
}

// The whole file, or nothing when it cannot be opened (the caller says what it expected).
std::optional<std::string> read_file(const std::filesystem::path& path);

}  // namespace manikind::toml_input
