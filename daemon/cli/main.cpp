// `manikin`: the command-line tool. Git-style subcommands; each prints a readable table by
// default and one JSON document with --json.
#include <cstdio>
#include <exception>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>
#include <spdlog/sinks/stdout_color_sinks.h>

#include "daemon/cli/commands.hpp"
#include "daemon/core/user_error.hpp"

int main(int argc, char** argv) {
    // Logs go to stderr so that stdout stays one clean JSON document under --json.
    spdlog::set_default_logger(spdlog::stderr_color_mt("manikin"));
    spdlog::set_pattern("%^%l%$: %v");

    CLI::App app{"manikin: thermal-manikin trials, heat fluxes with 95 % CIs, and the physics behind them"};
    app.require_subcommand(1);
    app.set_version_flag("--version", "manikin 0.1.0");
    bool verbose = false;
    app.add_flag("-v,--verbose", verbose, "Log debug detail to stderr");
    app.parse_complete_callback([&verbose] {
        if (verbose) spdlog::set_level(spdlog::level::debug);
    });

    manikind::cli::add_physics_commands(app);
    manikind::cli::add_selfcheck_command(app);
    manikind::cli::add_config_command(app);
    manikind::cli::add_analyze_command(app);
    manikind::cli::add_simulate_command(app);
    manikind::cli::add_reconcile_command(app);
    manikind::cli::add_demo_command(app);
    manikind::cli::add_thermoreg_command(app);
    manikind::cli::add_daemon_commands(app);
    manikind::cli::add_sim_commands(app);
    manikind::cli::add_probe_command(app);

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const manikind::UserError& e) {
        std::fprintf(stderr, "error: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "internal error: %s\n", e.what());
        return 1;
    }
    return 0;
}
