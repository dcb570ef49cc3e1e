#pragma once
// Every `manikin` subcommand registers itself through one of these functions, each in its own
// cmd_<name>.cpp; add_all_commands (app.cpp) calls them all, for main.cpp and for the tests
// that walk the command tree.
#include <CLI/CLI.hpp>

namespace manikind::cli {

void add_physics_commands(CLI::App& app);    // cmd_physics.cpp: `manikin physics ...`
void add_selfcheck_command(CLI::App& app);   // cmd_selfcheck.cpp: `manikin selfcheck`
void add_config_command(CLI::App& app);      // cmd_config.cpp: `manikin config check|show|token`
void add_analyze_command(CLI::App& app);     // cmd_analyze.cpp: `manikin analyze <campaign>`
void add_simulate_command(CLI::App& app);    // cmd_simulate.cpp: `manikin simulate-campaign`
void add_reconcile_command(CLI::App& app);   // cmd_reconcile.cpp: `manikin reconcile`
void add_clothing_command(CLI::App& app);    // cmd_clothing.cpp: `manikin clothing <campaign>`
void add_physio_command(CLI::App& app);      // cmd_physio.cpp: `manikin physio <campaign>`
void add_demo_command(CLI::App& app);        // cmd_demo.cpp: `manikin demo` (the README main job)
void add_thermoreg_command(CLI::App& app);   // cmd_thermoreg.cpp: `manikin thermoreg [sweep|speeds]`
void add_daemon_commands(CLI::App& app);     // cmd_daemon.cpp: status, campaign, setpoint, trial watch, results, export
void add_sim_commands(CLI::App& app);        // cmd_sim.cpp: `manikin sim serve`, `manikin replay`
void add_probe_command(CLI::App& app);       // cmd_sim.cpp: `manikin probe <device>`
void add_archive_command(CLI::App& app);     // cmd_archive.cpp: `manikin archive push`

// The whole `manikin` app: global options and every subcommand above.
void add_all_commands(CLI::App& app);

}  // namespace manikind::cli
