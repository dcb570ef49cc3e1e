#pragma once
// Every `manikin` subcommand registers itself through one of these functions, each in its own
// cmd_<name>.cpp; add_all_commands (app.cpp) calls them all, for main.cpp and for the tests
// that walk the command tree.
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

namespace manikind::cli {

void add_physics_commands(CLI::App& app);    // cmd_physics.cpp: `manikin physics ...`
void add_selfcheck_command(CLI::App& app);   // cmd_selfcheck.cpp: `manikin selfcheck`
void add_config_command(CLI::App& app);      // cmd_config.cpp: `manikin config check|show|token`
void add_analyze_command(CLI::App& app);     // cmd_analyze.cpp: `manikin analyze <campaign>`
void add_simulate_command(CLI::App& app);    // cmd_simulate.cpp: `manikin simulate-campaign`
void add_reconcile_command(CLI::App& app);   // cmd_reconcile.cpp: `manikin reconcile`
void add_clothing_command(CLI::App& app);    // cmd_clothing.cpp: `manikin clothing <campaign>`
void add_comfort_commands(CLI::App& app);    // cmd_comfort.cpp: `manikin calibrate`, `manikin teq` (ISO 14505-2)
void add_physio_command(CLI::App& app);      // cmd_physio.cpp: `manikin physio <campaign>`
void add_demo_command(CLI::App& app);        // cmd_demo.cpp: `manikin demo` (the README main job)
void add_thermoreg_command(CLI::App& app);   // cmd_thermoreg.cpp: `manikin thermoreg [sweep|speeds]`
void add_daemon_commands(CLI::App& app);     // cmd_daemon.cpp: status, campaign, setpoint, trial watch, results, export
void add_sim_commands(CLI::App& app);        // cmd_sim.cpp: `manikin sim serve`, `manikin replay`
void add_probe_command(CLI::App& app);       // cmd_sim.cpp: `manikin probe <device>`
void add_archive_command(CLI::App& app);     // cmd_archive.cpp: `manikin archive push`

// The whole `manikin` app: global options and every subcommand above.
void add_all_commands(CLI::App& app);

// The top-level commands each add_* function above adds, in the order of the whole tree (a test
// builds each group alone and compares).
struct CommandGroup {
    void (*add)(CLI::App&);
    std::vector<std::string_view> commands;
};
const std::vector<CommandGroup>& command_groups();

// What main.cpp builds: only the group of the command named in argv (building all ~50 commands'
// options was a third of `manikin status`'s start-up, issue 36), nothing but the global options
// for a bare --version, and the whole tree otherwise (--help, a misspelt command).
void add_commands_for(CLI::App& app, int argc, char** argv);
// After a parse error: the first word of argv that names no command where one is required, as
// "unknown command 'campaign chek' (did you mean 'campaign check'?)", or empty when every command
// word is known (CLI11's "A subcommand is required" said nothing of the misspelt word).
std::string unknown_command_message(const CLI::App& app, int argc, char** argv);
// Inside a group's add function: whether to build the command `name` (false only while
// add_commands_for builds another command of the same group).
bool building(std::string_view name);

}  // namespace manikind::cli
