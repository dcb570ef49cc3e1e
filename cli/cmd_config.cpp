// `manikin config check|show|token`: validate a configuration file before a lab relies on it.
#include <array>
#include <cstdio>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "cli/commands.hpp"
#include "daemon/config.hpp"
#include "base/user_error.hpp"

namespace manikind::cli {
namespace {

nlohmann::json to_json(const config::Config& c) {
    nlohmann::json instruments = nlohmann::json::object();
    for (const auto& [channel, s] : c.instruments)
        instruments[channel] = {{"accuracy", s.accuracy}, {"accuracy_of_reading", s.accuracy_of_reading},
                                {"distribution", s.distribution}};
    const auto& l = c.safety;
    return {{"lab", {{"name", c.lab_name}, {"mode", c.mode}, {"database", c.database.string()}, {"chamber", c.chamber},
                     {"manikin", c.manikin}}},
            {"logging", {{"level", c.log_level}}},
            {"safety", {{"max_skin_temp_c", l.max_skin_temp_c}, {"min_skin_temp_c", l.min_skin_temp_c},
                        {"max_heater_temp_c", l.max_heater_temp_c}, {"max_heater_power_w_m2", l.max_heater_power_w_m2},
                        {"min_chamber_temp_c", l.min_chamber_temp_c}, {"max_chamber_temp_c", l.max_chamber_temp_c},
                        {"min_chamber_rh_pct", l.min_chamber_rh_pct}, {"max_chamber_rh_pct", l.max_chamber_rh_pct},
                        {"watchdog_timeout_s", l.watchdog_timeout_s}}},
            {"steady_state", {{"window_min", c.steady_state.window_s / 60.0},
                              {"max_skin_fluctuation_c", c.steady_state.max_skin_fluctuation_c}}},
            {"instruments", instruments},
            {"api", {{"socket", c.api.socket}, {"tcp_port", c.api.tcp_port}, {"max_clients", c.api.max_clients},
                     {"idle_timeout_s", c.api.idle_timeout_s},
                     {"partial_grace_s", c.api.partial_grace_s}, {"max_clients_per_peer", c.api.max_clients_per_peer},
                     {"token_set", !c.api.token.empty()}}},
            {"warnings", c.warnings}};
}

std::vector<std::string> split_lines(const std::string& text) {
    std::vector<std::string> lines;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    return lines;
}

// 32 random bytes as 64 hex characters: 256 bits, far above what token_problem asks for.
std::string random_token() {
    std::array<unsigned char, 32> bytes{};
    std::ifstream urandom("/dev/urandom", std::ios::binary);
    if (!urandom.read(reinterpret_cast<char*>(bytes.data()), bytes.size())) {
        std::random_device rd;
        for (auto& b : bytes) b = static_cast<unsigned char>(rd() & 0xff);
    }
    std::string hex;
    for (const unsigned char b : bytes) {
        hex += "0123456789abcdef"[b >> 4];
        hex += "0123456789abcdef"[b & 0x0f];
    }
    return hex;
}

}  // namespace

void add_config_command(CLI::App& app) {
    auto* cmd = app.add_subcommand("config", "Validate or show a manikind configuration file (TOML)");
    cmd->require_subcommand(1);
    auto file = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto* check = cmd->add_subcommand("check", "Parse and validate a file as manikind does at start (register maps, "
                                                  "faults, socket path, real-mode keys, token); errors name file:line:column and the key");
    check->add_option("file", *file, "Configuration file")->required();
    check->add_flag("--json", *json, "Print the effective configuration as JSON");
    check->footer("Exit status 0 when the daemon would start with it, 5 when it has problems (each on its own line,\n"
                  "file:line:column: key), 2 when the file cannot be read (docs/cli.md).");
    check->callback([file, json] {
        if (!std::ifstream(*file)) throw UserError(fmt::format("{}: cannot open the configuration file", *file));
        // The file was read: what is wrong in it is the check's negative verdict, not a usage error.
        const auto c = [&] {
            try {
                auto loaded = config::load_config(*file);
                for (const auto& w : loaded.warnings) spdlog::warn("{}", w);
                config::require_valid(loaded);  // the daemon's own start-up check: the two never disagree
                return loaded;
            } catch (const UserError& e) {
                throw UserError::check_failed(e.what(), nlohmann::json{{"file", *file}, {"problems", split_lines(e.what())}});
            }
        }();
        if (*json) {
            std::printf("%s\n", to_json(c).dump(2).c_str());
            return;
        }
        std::printf("%s: ok (%s lab '%s', %zu instrument specs, %zu warnings)\n", file->c_str(), c.mode.c_str(),
                    c.lab_name.c_str(), c.instruments.size(), c.warnings.size());
    });
    auto show_json = std::make_shared<bool>(false);
    auto* show = cmd->add_subcommand("show", "Print the built-in default configuration (the simulated lab)");
    show->add_flag("--json", *show_json, "Print it as JSON: the effective configuration, as check --json does, and the TOML text");
    show->callback([show_json] {
        if (*show_json)
            std::printf("%s\n", nlohmann::json{{"config", to_json(config::default_config())}, {"toml", config::default_config_toml()}}
                                    .dump(2)
                                    .c_str());
        else
            std::printf("%s", config::default_config_toml());
    });
    auto token_json = std::make_shared<bool>(false);
    auto* token = cmd->add_subcommand("token", "Print a new random API token (64 hex characters) for [api] token");
    token->add_flag("--json", *token_json, "Print {\"token\": \"...\"}");
    token->callback([token_json] {
        const std::string t = random_token();
        if (*token_json) std::printf("%s\n", nlohmann::json{{"token", t}}.dump().c_str());
        else std::printf("%s\n", t.c_str());
    });
}

}  // namespace manikind::cli
