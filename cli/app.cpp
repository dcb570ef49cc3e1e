// The whole `manikin` command tree, built in one place for main.cpp and for the tests that walk it.
#include <memory>

#include <spdlog/spdlog.h>

#include "cli/commands.hpp"

namespace manikind::cli {

void add_all_commands(CLI::App& app) {
    app.require_subcommand(1);
    app.set_version_flag("--version", "manikin 0.1.0");
    auto verbose = std::make_shared<bool>(false);
    app.add_flag("-v,--verbose", *verbose, "Log debug detail to stderr");
    app.parse_complete_callback([verbose] {
        if (*verbose) spdlog::set_level(spdlog::level::debug);
    });
    add_physics_commands(app);
    add_selfcheck_command(app);
    add_config_command(app);
    add_analyze_command(app);
    add_simulate_command(app);
    add_reconcile_command(app);
    add_clothing_command(app);
    add_physio_command(app);
    add_demo_command(app);
    add_thermoreg_command(app);
    add_daemon_commands(app);
    add_sim_commands(app);
    add_probe_command(app);
    add_archive_command(app);
}

}  // namespace manikind::cli
