// The whole `manikin` command tree, built in one place for main.cpp and for the tests that walk it.
#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <fmt/core.h>

#include <spdlog/spdlog.h>

#include "cli/commands.hpp"

namespace manikind::cli {

const std::vector<CommandGroup>& command_groups() {
    static const std::vector<CommandGroup> groups{
        {add_physics_commands, {"physics"}},
        {add_selfcheck_command, {"selfcheck"}},
        {add_config_command, {"config"}},
        {add_analyze_command, {"analyze"}},
        {add_simulate_command, {"simulate-campaign"}},
        {add_reconcile_command, {"reconcile"}},
        {add_clothing_command, {"clothing"}},
        {add_comfort_commands, {"calibrate", "teq"}},
        {add_physio_command, {"physio"}},
        {add_demo_command, {"demo"}},
        {add_thermoreg_command, {"thermoreg"}},
        {add_daemon_commands,
         {"status", "campaign", "continue", "setpoint", "note", "notes", "ack", "shelve", "alarms", "trial", "results", "live", "campaigns", "log", "report", "export"}},
        {add_sim_commands, {"sim", "replay"}},
        {add_probe_command, {"probe"}},
        {add_archive_command, {"archive"}},
    };
    return groups;
}

namespace {

std::string_view only_command;  // set while add_commands_for builds one command's group

void add_global_options(CLI::App& app) {
    app.require_subcommand(1);
    app.set_version_flag("--version", "manikin 0.1.0");
    auto verbose = std::make_shared<bool>(false);
    app.add_flag("-v,--verbose", *verbose, "Log debug detail to stderr");
    app.parse_complete_callback([verbose] {
        if (*verbose) spdlog::set_level(spdlog::level::debug);
    });
}

}  // namespace

void add_all_commands(CLI::App& app) {
    add_global_options(app);
    for (const auto& g : command_groups()) g.add(app);
}

void add_commands_for(CLI::App& app, int argc, char** argv) {
    // The command is the first word that is not an option (the only options before it are
    // -v/--verbose, --help and --version, none taking a value).
    const char* command = nullptr;
    bool version = false;
    for (int i = 1; i < argc && !command; ++i) {
        if (std::strcmp(argv[i], "--version") == 0) version = true;
        if (argv[i][0] != '-') command = argv[i];
    }
    if (command) {
        for (const auto& g : command_groups())
            for (const auto name : g.commands)
                if (name == command) {
                    add_global_options(app);
                    only_command = name;
                    g.add(app);
                    only_command = {};
                    return;
                }
    } else if (version) {
        add_global_options(app);  // `manikin --version` needs no command
        return;
    }
    add_all_commands(app);  // --help, a misspelt command: the whole tree, so the message lists every command
}

namespace {

// Edits (insert, delete, substitute, swap of neighbours) from a to b: "chek" is one from "check".
std::size_t edit_distance(std::string_view a, std::string_view b) {
    std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1, 0));
    for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
    for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i)
        for (std::size_t j = 1; j <= b.size(); ++j) {
            d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
        }
    return d[a.size()][b.size()];
}

// Whether `name` (--socket) takes a value at `app` or any command under it: an option given before
// the command word it belongs to (`campaign --socket s abort`) still takes the next word.
bool takes_value(const CLI::App& app, const std::string& name) {
    if (const CLI::Option* opt = app.get_option_no_throw(name)) return opt->get_expected_min() > 0;
    for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
        if (takes_value(*sub, name)) return true;
    return false;
}

std::size_t common_prefix(std::string_view a, std::string_view b) {
    std::size_t n = 0;
    while (n < a.size() && n < b.size() && a[n] == b[n]) ++n;
    return n;
}

}  // namespace

std::string unknown_command_message(const CLI::App& app, int argc, char** argv) {
    const CLI::App* at = &app;
    std::string path;  // the command words known so far
    for (int i = 1; i < argc; ++i) {
        const std::string_view word = argv[i];
        if (word.empty() || word[0] == '-') {
            // An option; one that takes a value (and has no '=') takes the next word with it.
            if (word.find('=') == std::string_view::npos && takes_value(*at, std::string(word))) ++i;
            continue;
        }
        std::vector<std::string> names;
        for (const CLI::App* sub : at->get_subcommands([](const CLI::App*) { return true; })) names.push_back(sub->get_name());
        if (std::find(names.begin(), names.end(), word) != names.end()) {
            at = at->get_subcommand(std::string(word));
            path += (path.empty() ? "" : " ") + std::string(word);
            continue;
        }
        if (names.empty() || at->get_require_subcommand_min() == 0) return {};  // an argument, not a command word
        std::sort(names.begin(), names.end());
        // The nearest name: within two edits, or sharing its first four letters or more
        // ("clothes" -> "clothing"); the fewest edits wins.
        std::string best;
        std::size_t best_d = std::string::npos;
        for (const auto& n : names) {
            const std::size_t d = edit_distance(word, n);
            if ((d <= 2 || common_prefix(word, n) >= 4) && d < best_d) best_d = d, best = n;
        }
        const std::string prefix = path.empty() ? "" : path + " ";
        std::string list;
        for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
        return fmt::format("unknown command '{}{}'{}; the commands{} are: {}", prefix, word,
                           best.empty() ? "" : fmt::format(" (did you mean '{}{}'?)", prefix, best),
                           path.empty() ? "" : " of '" + path + "'", list);
    }
    return {};
}

bool building(std::string_view name) { return only_command.empty() || name == only_command; }

}  // namespace manikind::cli
