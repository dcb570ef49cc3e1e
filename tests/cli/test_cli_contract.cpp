// The one CLI contract (docs/cli.md): every command takes --json; under --json an error is one
// {"error": {...}} object on stdout; exit statuses 0-5 mean the same everywhere; --db works
// wherever a campaign is read; heat flux has one sign in every command.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "../daemon/daemon_process.hpp"
#include "cli/commands.hpp"
#include "physics/sign_convention.hpp"
#include "run_cli.hpp"

using manikind::test::CliResult;
using manikind::test::DaemonProcess;
using manikind::test::run_manikin;
namespace fs = std::filesystem;

namespace {

fs::path contract_dir(const std::string& name) {
    const auto dir = fs::temp_directory_path() / ("manikind-contract-" + name + "-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

// Named subcommands (CLI11 keeps option groups as unnamed ones).
std::vector<CLI::App*> subcommands_of(CLI::App& app) {
    return app.get_subcommands([](CLI::App* sub) { return !sub->get_name().empty(); });
}

// Every subcommand a user can run: the leaves, and any command that runs without a subcommand.
void runnable_commands(CLI::App& app, const std::string& path, std::vector<std::pair<std::string, CLI::App*>>& out) {
    const auto subs = subcommands_of(app);
    if (subs.empty() || app.get_require_subcommand_min() == 0) out.emplace_back(path, &app);
    for (auto* sub : subs) runnable_commands(*sub, path + " " + sub->get_name(), out);
}

// stdout must be exactly one JSON object holding only "error", whose exit_code is the process's.
nlohmann::json error_of(const CliResult& r) {
    INFO("stdout: " << r.out);
    const auto doc = nlohmann::json::parse(r.out, nullptr, false);
    REQUIRE_FALSE(doc.is_discarded());
    REQUIRE(doc.is_object());
    REQUIRE(doc.size() == 1);
    REQUIRE(doc.contains("error"));
    const auto& e = doc["error"];
    CHECK(e["code"].is_string());
    CHECK_FALSE(e["message"].get<std::string>().empty());
    CHECK(e["exit_code"] == r.exit_code);
    return e;
}

}  // namespace

TEST_CASE("cli contract: every runnable subcommand takes --json", "[cli][contract]") {
    CLI::App app;
    manikind::cli::add_all_commands(app);
    std::vector<std::pair<std::string, CLI::App*>> commands;
    for (auto* sub : subcommands_of(app)) runnable_commands(*sub, sub->get_name(), commands);
    std::vector<std::string> missing;
    for (const auto& [path, cmd] : commands)
        if (!cmd->get_option_no_throw("--json")) missing.push_back(path);
    INFO("runnable commands found: " << commands.size());
    CHECK(commands.size() >= 30);  // the walk must see the whole tree, not an empty app
    for (const auto& m : missing) FAIL_CHECK("`manikin " << m << "` has no --json");
    CHECK(missing.empty());
}

TEST_CASE("cli contract: each command group adds exactly the commands its table names, so main builds the right "
          "one alone",
          "[cli][contract]") {
    std::vector<std::string> from_groups;
    for (const auto& g : manikind::cli::command_groups()) {
        CLI::App alone;
        g.add(alone);
        std::vector<std::string> built, listed(g.commands.begin(), g.commands.end());
        for (auto* sub : subcommands_of(alone)) built.push_back(sub->get_name());
        CHECK(built == listed);
        from_groups.insert(from_groups.end(), listed.begin(), listed.end());
    }
    CLI::App whole;
    manikind::cli::add_all_commands(whole);
    std::vector<std::string> all;
    for (auto* sub : subcommands_of(whole)) all.push_back(sub->get_name());
    CHECK(all == from_groups);
    CHECK(all.size() >= 25);
    // The program built from argv: a command's own options are there, others' are not needed.
    CHECK(manikind::test::run_manikin("status --help > /dev/null").exit_code == 0);
    CHECK(manikind::test::run_manikin("-v export --help > /dev/null").exit_code == 0);
    const auto version = manikind::test::run_manikin("--version");
    CHECK(version.exit_code == 0);
    CHECK(version.out == "manikin 0.1.0\n");
    const auto help = manikind::test::run_manikin("--help");  // the whole tree: every command listed
    CHECK(help.exit_code == 0);
    for (const auto& name : all) CHECK_THAT(help.out, Catch::Contains(name));
    CHECK(manikind::test::run_manikin("statsu > /dev/null 2>&1").exit_code == 2);
}

TEST_CASE("cli contract: input and usage errors under --json are one error object, exit 2", "[cli][contract]") {
    const auto dir = contract_dir("input");
    SECTION("a campaign folder that does not exist") {
        const auto r = run_manikin("analyze " + (dir / "none").string() + " --json");
        CHECK(r.exit_code == 2);
        CHECK(error_of(r)["code"] == "bad_input");
    }
    SECTION("a database that does not exist, for reconcile --db") {
        const auto r = run_manikin("reconcile --db " + (dir / "none.db").string() + " --json");
        CHECK(r.exit_code == 2);
        CHECK_THAT(error_of(r)["message"].get<std::string>(), Catch::Contains("no such database"));
    }
    SECTION("an option the command does not have (a CLI11 parse error)") {
        const auto r = run_manikin("physics psychro --temp 35 --rh 10 --bogus --json");
        CHECK(r.exit_code == 2);
        CHECK(error_of(r)["code"] == "usage");
    }
    SECTION("a value outside an option's range") {
        const auto r = run_manikin("physics psychro --temp 35 --rh 150 --json");
        CHECK(r.exit_code == 2);
        error_of(r);
    }
    SECTION("a configuration file that cannot be read is input, not a verdict") {
        const auto r = run_manikin("config check " + (dir / "none.toml").string() + " --json");
        CHECK(r.exit_code == 2);
        CHECK(error_of(r)["code"] == "bad_input");
    }
    SECTION("without --json: nothing on stdout, `error: ...` on stderr, the same status") {
        const auto quiet = run_manikin("analyze " + (dir / "none").string() + " 2>/dev/null");
        CHECK(quiet.exit_code == 2);
        CHECK(quiet.out.empty());
        const auto both = run_manikin("analyze " + (dir / "none").string() + " 2>&1");
        CHECK(both.out.rfind("error: ", 0) == 0);
        CHECK(run_manikin("physics psychro --temp 35 --rh 10 --bogus 2>/dev/null").exit_code == 2);
    }
    SECTION("an argument that is not UTF-8 is a usage error naming it, not an internal error") {
        // A note's campaign name typed in a Latin-1 terminal went into the JSON request and threw.
        const auto r = run_manikin("note --socket " + (dir / "none.sock").string() + " --campaign \"$(printf 'caf\\351')\" hello --json");
        CHECK(r.exit_code == 2);
        CHECK(error_of(r)["code"] == "bad_usage");
        CHECK_THAT(error_of(r)["message"].get<std::string>(), Catch::Contains("not UTF-8") && Catch::Contains("caf\\xE9"));
        const auto plain = run_manikin("note --campaign \"$(printf '\\377')\" x 2>&1");
        CHECK(plain.exit_code == 2);
        CHECK(plain.out.find("internal error") == std::string::npos);
    }
    SECTION("a misspelt command is named with the nearest one, at the top and inside a command (issue 64)") {
        const auto top = run_manikin("clothes 2>&1");
        CHECK(top.exit_code == 2);
        CHECK_THAT(top.out, Catch::Contains("unknown command 'clothes' (did you mean 'clothing'?)"));
        const auto inner = run_manikin("campaign chek x.toml --json");
        CHECK(inner.exit_code == 2);
        CHECK_THAT(error_of(inner)["message"].get<std::string>(),
                   Catch::Contains("unknown command 'campaign chek' (did you mean 'campaign check'?)") &&
                       Catch::Contains("the commands of 'campaign' are: "));
        // An option's value is not taken for a command word; far from every name, no guess.
        const auto socket = run_manikin("campaign --socket /nowhere.sock zzzzzz 2>&1");
        CHECK_THAT(socket.out, Catch::Contains("unknown command 'campaign zzzzzz';"));
        CHECK(socket.out.find("did you mean") == std::string::npos);
        // The footer's exit statuses include 6 (docs/cli.md).
        CHECK_THAT(run_manikin("--help").out, Catch::Contains("6 a campaign waited for did not"));
    }
    SECTION("--help is not an error, even with --json") {
        const auto r = run_manikin("thermoreg --help --json");
        CHECK(r.exit_code == 0);
        CHECK_THAT(r.out, Catch::Contains(manikind::physics::heat_flux_sign));
    }
    fs::remove_all(dir);
}

TEST_CASE("cli contract: a daemon socket that does not exist is exit 3", "[cli][contract]") {
    const auto dir = contract_dir("nodaemon");
    for (const std::string cmd : {"status", "live", "results", "trial watch", "setpoint --chamber-temp 30 --chamber-rh 40"}) {
        INFO(cmd);
        const auto r = run_manikin(cmd + " --json --socket " + (dir / "none.sock").string());
        CHECK(r.exit_code == 3);
        CHECK(error_of(r)["code"] == "daemon_unreachable");
    }
    fs::remove_all(dir);
}

TEST_CASE("cli contract: checks with a negative verdict exit 5", "[cli][contract]") {
    const auto dir = contract_dir("verdict");
    const auto config = (dir / "lab.toml").string();
    std::ofstream(config) << "[lab]\nname = \"x\"\n[devices.chamber]\nregister_map = \"/dev/zero\"\n";
    auto r = run_manikin("config check " + config + " --json");
    CHECK(r.exit_code == 5);
    auto e = error_of(r);
    CHECK(e["code"] == "check_failed");
    CHECK(e["details"]["file"] == config);
    CHECK_FALSE(e["details"]["problems"].empty());

    const auto plan = (dir / "typo.toml").string();
    std::ofstream(plan) << "name = \"typo\"\nreplicate = 1\nbuiltin_cases = \"table-s3\"\n";
    r = run_manikin("campaign check " + plan + " --json");
    CHECK(r.exit_code == 5);
    CHECK_THAT(error_of(r)["message"].get<std::string>(), Catch::Contains("did you mean 'replicates'"));

    // The shipped example passes: the same command can say yes.
    r = run_manikin(std::string("campaign check ") + MANIKIND_CONFIG_DIR "/campaign-example.toml --json");
    CHECK(r.exit_code == 0);
    CHECK(nlohmann::json::parse(r.out)["ok"] == true);
    fs::remove_all(dir);
}

TEST_CASE("cli contract: the daemon's refusals exit 4, no results yet is an answer", "[cli][contract]") {
    const auto dir = contract_dir("refused");
    const std::string socket = (dir / "d.sock").string();
    auto d = DaemonProcess::spawn({std::string(MANIKIND_BIN_DIR) + "/manikind", "--virtual", "--socket", socket, "--database",
                                   (dir / "d.db").string(), "--campaign", std::string(MANIKIND_CONFIG_DIR) + "/campaign-example.toml"});
    REQUIRE(d.read_until("control socket"));

    auto r = run_manikin("setpoint --chamber-temp 200 --chamber-rh 40 --json --socket " + socket);
    CHECK(r.exit_code == 4);
    auto e = error_of(r);
    CHECK(e["code"] == "refused");
    CHECK_THAT(e["message"].get<std::string>(), Catch::Contains("safety"));

    r = run_manikin("campaign pause --token not-the-token --json --socket " + socket);
    CHECK(r.exit_code == 4);
    CHECK(error_of(r)["code"] == "refused");

    r = run_manikin("setpoint --chamber-temp 30 --chamber-rh 40 --json --socket " + socket);
    CHECK(r.exit_code == 0);
    CHECK(nlohmann::json::parse(r.out)["ok"] == true);

    // The campaign has just started: no results, said in one document, exit 0.
    r = run_manikin("results --json --socket " + socket);
    CHECK(r.exit_code == 0);
    const auto results = nlohmann::json::parse(r.out);
    CHECK(results["campaign"] == "humid-series-2026-11");
    CHECK(results["cases"].empty());
    CHECK_THAT(results["note"].get<std::string>(), Catch::Contains("no results yet"));

    // trial watch under --json is one document, not a stream.
    r = run_manikin("trial watch --json --socket " + socket);
    CHECK(r.exit_code == 0);
    CHECK(nlohmann::json::parse(r.out)["campaign"] == "humid-series-2026-11");
    CHECK(WEXITSTATUS(d.terminate()) == 0);
    fs::remove_all(dir);
}

TEST_CASE("cli contract: probe --write beyond the register map's limits is refused, exit 4, with the readings",
          "[cli][contract]") {
    const auto dir = contract_dir("probe");
    auto lab = DaemonProcess::spawn({std::string(MANIKIND_BIN_DIR) + "/manikin", "sim", "serve", "--json", "--speed", "10",
                                     "--runtime-dir", (dir / "rt").string()});
    REQUIRE(lab.read_until("\"chamber\""));
    const auto& output = lab.output();
    const auto line_start = output.rfind('\n', output.find("\"chamber\"")), line_end = output.find('\n', output.find("\"chamber\""));
    const auto endpoints = nlohmann::json::parse(
        output.substr(line_start == std::string::npos ? 0 : line_start + 1, line_end - (line_start == std::string::npos ? 0 : line_start + 1)));
    const std::string port = std::to_string(endpoints["chamber"]["port"].get<int>());

    auto r = run_manikin("probe chamber --port " + port + " --timeout 2 --write air_temp_remote_setpoint_c=80 --json");
    CHECK(r.exit_code == 4);
    const auto e = error_of(r);
    CHECK(e["code"] == "refused");
    REQUIRE(e["details"]["writes"].size() == 1);
    CHECK(e["details"]["writes"][0]["ok"] == false);
    CHECK_FALSE(e["details"]["samples"].empty());

    r = run_manikin("probe chamber --port " + port + " --timeout 2 --write air_temp_remote_setpoint_c=35 --json");
    CHECK(r.exit_code == 0);
    CHECK(nlohmann::json::parse(r.out)["writes"][0]["ok"] == true);

    r = run_manikin("probe chamber --port " + port + " --timeout 2 --write air_temp_remote_setpoint_c=hot --json");
    CHECK(r.exit_code == 2);
    error_of(r);
    lab.terminate();
    fs::remove_all(dir);
}

TEST_CASE("cli contract: reconcile reads a campaign from the daemon's database as analyze does", "[cli][contract][reconcile][proof]") {
    const auto dir = contract_dir("db");
    REQUIRE(run_manikin("demo --cases 2 --replicates 2 --json --out " + dir.string() + " 2>/dev/null").exit_code == 0);
    const std::string db = (dir / "manikind.db").string();
    const auto campaigns = nlohmann::json::parse(run_manikin("campaigns --json --db " + db).out);
    REQUIRE(campaigns.size() == 1);
    const std::string name = campaigns[0]["name"];

    const std::string fast = " --simulations 200 --json";
    const auto by_name = run_manikin("reconcile --db " + db + " --campaign " + name + fast);
    REQUIRE(by_name.exit_code == 0);
    const auto newest = run_manikin("reconcile --db " + db + fast);  // no name: the newest campaign
    REQUIRE(newest.exit_code == 0);
    // The demo also wrote the same campaign out as a folder: both sources must give the same fit.
    const auto folder = run_manikin("reconcile " + (dir / "campaign").string() + fast);
    REQUIRE(folder.exit_code == 0);
    const auto a = nlohmann::json::parse(by_name.out), b = nlohmann::json::parse(newest.out), c = nlohmann::json::parse(folder.out);
    CHECK_THAT(a["campaign"].get<std::string>(), Catch::Contains(name));
    CHECK(a["before"]["n_points"] == c["before"]["n_points"]);
    // (the folder holds the samples as text, so allow for its rounding)
    CHECK(a["before"]["rmse_w_m2"].get<double>() == Approx(c["before"]["rmse_w_m2"].get<double>()).epsilon(1e-3));
    CHECK(b["before"]["rmse_w_m2"] == a["before"]["rmse_w_m2"]);
    // analyze takes the same options and reads the same campaign.
    const auto analyzed = run_manikin("analyze --db " + db + " --json");
    REQUIRE(analyzed.exit_code == 0);
    CHECK(nlohmann::json::parse(analyzed.out)["cases"].size() == 2);

    const auto unknown = run_manikin("reconcile --db " + db + " --campaign no-such-campaign --json");
    CHECK(unknown.exit_code == 2);
    error_of(unknown);
    fs::remove_all(dir);
}

TEST_CASE("cli contract: thermoreg prints heat flows with the sign physics and analyze use (positive = lost)",
          "[cli][contract][thermoreg]") {
    // Fig. 4's hot, sunny exposure: air 41 °C and MRT 55 °C above the skin, so the body gains heat by
    // convection and radiation (negative losses) and loses it by sweating (positive).
    const auto r = run_manikin("thermoreg --duration 30min --json");
    REQUIRE(r.exit_code == 0);
    const auto j = nlohmann::json::parse(r.out);
    CHECK_THAT(j["heat_flux_sign"].get<std::string>(), Catch::Contains(manikind::physics::heat_flux_sign));
    const auto& f = j["final"];
    CHECK(f["mean_skin_temp_c"].get<double>() < 41.0);
    CHECK(f["convection_loss_w"].get<double>() < 0.0);
    CHECK(f["radiation_loss_w"].get<double>() < 0.0);
    CHECK(f["evaporation_loss_w"].get<double>() > 0.0);
    // The balance in the printed signs: stored = produced - lost, at every printed step.
    for (const auto& s : j["series"]) {
        const double lost = s["evaporation_loss_w"].get<double>() + s["convection_loss_w"].get<double>() +
                            s["radiation_loss_w"].get<double>() + s["respiration_loss_w"].get<double>();
        CHECK(s["storage_w"].get<double>() == Approx(s["metabolic_production_w"].get<double>() - lost).margin(0.01));
    }
    // physics h-c, same air and the final skin temperature: convection has the same sign.
    const auto h = run_manikin(fmt::format("physics h-c --air-temp 41 --rh 20 --skin-temp {:.2f} --wettedness 0 --json",
                                           f["mean_skin_temp_c"].get<double>()));
    REQUIRE(h.exit_code == 0);
    const auto hj = nlohmann::json::parse(h.out);
    CHECK(hj["heat_flux_sign"] == manikind::physics::heat_flux_sign);
    CHECK(std::signbit(hj["q_convection_w_m2"].get<double>()) == std::signbit(f["convection_loss_w"].get<double>()));
    // The text says the same convention it prints.
    const auto text = run_manikin("thermoreg --duration 10min");
    REQUIRE(text.exit_code == 0);
    CHECK_THAT(text.out, Catch::Contains(manikind::physics::heat_flux_sign));
}
