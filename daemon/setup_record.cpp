#include "daemon/setup_record.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <sstream>
#include <vector>

#include "drivers/register_map.hpp"
#include "base/toml_input.hpp"

namespace manikind {
namespace {

// The API token, and an archive conninfo that carries a password, must not travel into the
// trial records and from there into a lab-wide archive: their values are replaced.
bool carries_password(std::string_view conninfo) {
    std::string lower(conninfo);
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char ch) { return std::tolower(ch); });
    if (lower.find("password") != std::string::npos) return true;
    // A URI's user:password@host.
    const auto scheme = lower.find("://");
    if (scheme == std::string::npos) return false;
    const auto at = lower.find('@', scheme + 3);
    const auto slash = lower.find('/', scheme + 3);
    return at != std::string::npos && (slash == std::string::npos || at < slash) &&
           lower.substr(scheme + 3, at - scheme - 3).find(':') != std::string::npos;
}

bool is_ascii(std::string_view s) {
    return std::all_of(s.begin(), s.end(), [](char ch) { return static_cast<unsigned char>(ch) < 0x80; });
}

}  // namespace

std::string redact_secrets(const std::string& toml_text) {
    toml::table root;
    try {
        root = toml_input::parse(toml_text, "configuration");
    } catch (const std::exception&) {
        return "";  // cannot tell where the secrets are: keep none of it
    }
    std::vector<std::string> lines;
    {
        std::istringstream in(toml_text);
        for (std::string line; std::getline(in, line);) lines.push_back(line);
    }
    const auto redact = [&](const toml::node* node) {
        if (!node) return;
        const auto& region = node->source();
        const auto first = static_cast<std::size_t>(region.begin.line) - 1;
        const auto last = std::min(static_cast<std::size_t>(region.end.line) - 1, lines.size() - 1);
        if (first >= lines.size()) return;
        std::string& line = lines[first];
        const auto begin_col = static_cast<std::size_t>(region.begin.column) - 1;
        if (is_ascii(line) && begin_col <= line.size()) {
            // Columns count characters; in an ASCII line they are bytes.
            const std::string rest = first == last && is_ascii(lines[last]) && region.end.column - 1 <= lines[last].size()
                                         ? lines[last].substr(static_cast<std::size_t>(region.end.column) - 1)
                                         : std::string();
            line = line.substr(0, begin_col) + "\"(redacted)\"" + rest;
        } else {
            line = "# (a line holding a secret, redacted)";
        }
        for (std::size_t i = first + 1; i <= last; ++i) lines[i] = "# (redacted)";
    };
    if (const auto token = root.at_path("api.token").value<std::string>(); !token || !token->empty())
        redact(root.at_path("api.token").node());  // an empty token (the daemon makes one) is no secret
    if (const auto conninfo = root.at_path("archive.postgresql").value<std::string>(); conninfo && carries_password(*conninfo))
        redact(root.at_path("archive.postgresql").node());
    std::string out;
    for (const auto& line : lines) out += line + "\n";
    if (!toml_text.empty() && toml_text.back() != '\n' && !out.empty()) out.pop_back();
    return out;
}

recorder::Setup setup_of(const config::Config& config) {
    nlohmann::ordered_json calibration;
    auto& instruments = calibration["instruments"] = nlohmann::ordered_json::object();
    for (const auto& [channel, spec] : config.instruments)  // a std::map: sorted, so the text is stable
        instruments[channel] = {{"accuracy", spec.accuracy},
                                {"accuracy_of_reading", spec.accuracy_of_reading},
                                {"distribution", spec.distribution}};
    auto& maps = calibration["register_maps"] = nlohmann::ordered_json::object();
    for (const auto& [device, modbus] :
         {std::pair{"chamber", &config.devices.chamber}, std::pair{"datalogger", &config.devices.datalogger}})
        maps[device] = {{"setting", modbus->register_map},
                        {"toml", register_map_text(modbus->register_map, device, config.source_dir)}};
    calibration["steady_state"] = {{"window_s", config.steady_state.window_s},
                                   {"max_skin_fluctuation_c", config.steady_state.max_skin_fluctuation_c}};
    return {config.lab_name, config.chamber, config.manikin, calibration.dump(), redact_secrets(config.source_text)};
}

}  // namespace manikind
