// The whole `manikin` command tree, built in one place for main.cpp and for the tests that walk it.
#include <cstring>
#include <memory>

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
         {"status", "campaign", "setpoint", "note", "notes", "alarms", "trial", "results", "live", "campaigns", "log", "report", "export"}},
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

bool building(std::string_view name) { return only_command.empty() || name == only_command; }

}  // namespace manikind::cli
