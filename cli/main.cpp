// `manikin`: the command-line tool. Git-style subcommands; each prints a readable table by
// default and one JSON document with --json. The contract every command follows (JSON errors,
// exit statuses, sign convention) is docs/cli.md; errors are turned into it here, in one place.
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <spdlog/sinks/stdout_color_sinks.h>

#include "cli/commands.hpp"
#include "base/heap.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"

namespace {

using manikind::ExitStatus;

// Scanned before parsing, so that even a parse error is reported as JSON; "--" ends the options.
bool json_requested(int argc, char** argv) {
    for (int i = 1; i < argc; ++i) {
        if (std::strcmp(argv[i], "--") == 0) return false;
        if (std::strcmp(argv[i], "--json") == 0) return true;
    }
    return false;
}

// The one error output: `{"error": {...}}` alone on stdout under --json, `error: ...` on stderr otherwise.
int report_error(bool json, const std::string& code, const std::string& message, ExitStatus status,
                 const nlohmann::json& details = nullptr) {
    const int exit_code = static_cast<int>(status);
    if (json) {
        nlohmann::json error = {{"code", code}, {"message", message}, {"exit_code", exit_code}};
        if (!details.is_null()) error["details"] = details;
        std::fflush(stdout);
        std::printf("%s\n", nlohmann::json{{"error", error}}.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
    } else {
        std::fprintf(stderr, "%s: %s\n", status == ExitStatus::internal ? "internal error" : "error", message.c_str());
    }
    return exit_code;
}

}  // namespace

int main(int argc, char** argv) {
    manikind::keep_freed_memory_for_reuse();  // base/heap.hpp: reconcile's matrices, reused not re-faulted
    // Logs go to stderr so that stdout stays one clean JSON document under --json.
    spdlog::set_default_logger(spdlog::stderr_color_mt("manikin"));
    spdlog::set_pattern("%^%l%$: %v");
    const bool json = json_requested(argc, argv);

    CLI::App app{"manikin: thermal-manikin trials, heat fluxes with 95 % CIs, and the physics behind them"};
    app.footer("Every command takes --json. Exit status: 0 ok, 1 internal error, 2 bad usage or input, 3 daemon not\n"
               "reachable, 4 refused, 5 negative verdict (a check found problems), 6 a campaign waited for did not\n"
               "end done. docs/cli.md has the contract.");
    // Every argument is UTF-8 text (names, notes, paths): one that is not went into a JSON request
    // and came back as "internal error" (issue 60); it is a usage error, named here.
    for (int i = 1; i < argc; ++i)
        if (!manikind::is_utf8(argv[i]))
            return report_error(json, "bad_usage",
                                fmt::format("argument {} ('{}') is not UTF-8 text: manikin takes its names, texts and paths "
                                            "as UTF-8 (check the terminal's or the script's encoding)",
                                            i, manikind::printable(argv[i], 80)),
                                ExitStatus::bad_input);
    try {
        manikind::cli::add_commands_for(app, argc, argv);
        app.parse(argc, argv);
    } catch (const CLI::Success& e) {
        return app.exit(e);  // --help and --version: text, status 0, even with --json
    } catch (const CLI::ParseError& e) {
        if (const auto unknown = manikind::cli::unknown_command_message(app, argc, argv); !unknown.empty())
            return report_error(json, "usage", unknown, ExitStatus::bad_input);
        if (!json) {
            app.exit(e);  // CLI11's own message and "Run with --help"; the status is ours
            return static_cast<int>(ExitStatus::bad_input);
        }
        return report_error(true, "usage", e.what(), ExitStatus::bad_input);
    } catch (const manikind::UserError& e) {
        if (e.code() == "verdict_in_output" && json) return e.exit_code();  // the document printed says it
        return report_error(json, e.code(), e.what(), e.status(), e.details());
    } catch (const std::exception& e) {
        return report_error(json, "internal", e.what(), ExitStatus::internal);
    }
    return 0;
}
