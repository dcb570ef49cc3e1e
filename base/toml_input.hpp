#pragma once
// Shared input plumbing for the TOML files the daemon reads (config, twin versions, register
// maps): one place decides how a parse error and a node's position are reported
// ("file:line:column"), and how a file is read.
#include <cstdint>
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

// Our TOML files are a few kB; 1 MiB is generous and still bounds what a wrong path costs.
inline constexpr std::uintmax_t max_toml_bytes = std::uintmax_t{1} << 20;

// The whole of a regular file of at most `max_bytes`, or a manikind::UserError
// "<path>: <why>" naming `what` was expected ("a TOML configuration file"). A directory, a FIFO,
// a device (/dev/zero) or a file over the bound is refused after a stat, without reading it all.
std::string read_text_file(const std::filesystem::path& path, const std::string& what,
                           std::uintmax_t max_bytes = max_toml_bytes);

// The same bounded read, or nothing when the file is refused (the caller says what it expected).
std::optional<std::string> read_file(const std::filesystem::path& path);

}  // namespace manikind::toml_input
