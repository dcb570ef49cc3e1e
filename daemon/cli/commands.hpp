#pragma once
// Every `manikin` subcommand registers itself through one of these functions, called from
// main.cpp. Each lives in its own cmd_<name>.cpp.
#include <CLI/CLI.hpp>

namespace manikind::cli {

void add_physics_commands(CLI::App& app);    // cmd_physics.cpp: `manikin physics ...`
void add_selfcheck_command(CLI::App& app);   // cmd_selfcheck.cpp: `manikin selfcheck`
void add_config_command(CLI::App& app);      // cmd_config.cpp: `manikin config check|show`
void add_analyze_command(CLI::App& app);     // cmd_analyze.cpp: `manikin analyze <campaign>`
void add_simulate_command(CLI::App& app);    // cmd_simulate.cpp: `manikin simulate-campaign`
void add_reconcile_command(CLI::App& app);   // cmd_reconcile.cpp: `manikin reconcile`
void add_demo_command(CLI::App& app);        // cmd_demo.cpp: `manikin demo` (the README main job)
void add_thermoreg_command(CLI::App& app);
void add_daemon_commands(CLI::App& app);
void add_sim_commands(CLI::App& app);        // cmd_sim.cpp: `manikin sim serve`, `manikin replay`
void add_probe_command(CLI::App& app);       // cmd_sim.cpp: `manikin probe <device>`     // cmd_daemon.cpp: status, campaign, setpoint, trial watch, results, export   // cmd_thermoreg.cpp: `manikin thermoreg [sweep|speeds]`

}  // namespace manikind::cli
