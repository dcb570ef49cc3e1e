// The `manikin` command tree, built in one place for main.cpp and for the tests that walk it.
#include <cstring>
#include <memory>
#include <string_view>

#include <spdlog/spdlog.h>

#include "daemon/cli/commands.hpp"

namespace manikind::cli {

namespace {

using Adder = void (*)(CLI::App&);

// Each group of subcommands in the order `manikin --help` lists them, with the names it adds.
struct Group {
    Adder add;
    std::initializer_list<std::string_view> names;
};
const Group kGroups[] = {
    {add_physics_commands, {"physics"}},
    {add_selfcheck_command, {"selfcheck"}},
    {add_config_command, {"config"}},
    {add_analyze_command, {"analyze"}},
    {add_simulate_command, {"simulate-campaign"}},
    {add_reconcile_command, {"reconcile"}},
    {add_demo_command, {"demo"}},
    {add_thermoreg_command, {"thermoreg"}},
    {add_daemon_commands, {"status", "campaign", "setpoint", "trial", "results", "live", "campaigns", "log", "export"}},
    {add_sim_commands, {"sim", "replay"}},
    {add_probe_command, {"probe"}},
    {add_archive_command, {"archive"}},
};

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
    for (const Group& g : kGroups) g.add(app);
}

void add_commands_for(CLI::App& app, int argc, const char* const* argv) {
    // The first argument that is not an option names the subcommand (the only global options,
    // -v, --help and --version, take no value).
    const char* name = nullptr;
    for (int i = 1; i < argc && !name; ++i) {
        if (std::strcmp(argv[i], "--") == 0) break;
        if (argv[i][0] != '-') name = argv[i];
    }
    if (name) {
        for (const Group& g : kGroups) {
            for (const std::string_view n : g.names) {
                if (n == name) {
                    add_global_options(app);
                    g.add(app);
                    return;
                }
            }
        }
    }
    add_all_commands(app);  // no or an unknown subcommand: the whole tree, for help and "did you mean"
}

}  // namespace manikind::cli
