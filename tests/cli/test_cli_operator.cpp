// The operator's console commands: campaign check (the daemon's parser, typos are errors),
// campaigns (what a database holds), and status / trial watch / live against a running daemon,
// whose output in a pipe carries no terminal control codes.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "../daemon/daemon_process.hpp"
#include "daemon/lab_daemon.hpp"
#include "run_cli.hpp"

using manikind::test::DaemonProcess;
using manikind::test::run_manikin;
namespace fs = std::filesystem;

namespace {
fs::path operator_dir(const std::string& name) {
    const auto dir = fs::temp_directory_path() / ("manikind-cli-" + name + "-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}
}  // namespace

TEST_CASE("manikin campaign check: the example passes, a misspelt key fails with file, line, column and a suggestion",
          "[cli][campaign]") {
    const auto ok = run_manikin(std::string("campaign check ") + MANIKIND_CONFIG_DIR "/campaign-example.toml");
    CHECK(ok.exit_code == 0);
    CHECK(ok.out.find("ok: campaign 'humid-series-2026-11', 2 case(s) x 3 replicate(s)") != std::string::npos);
    const auto dir = operator_dir("check");
    {
        std::ofstream bad(dir / "typo.toml");
        bad << "name = \"typo\"\nreplicate = 1\nbuiltin_cases = \"table-s3\"\n";
    }
    const auto r = run_manikin("campaign check " + (dir / "typo.toml").string() + " 2>&1");
    CHECK(r.exit_code == 5);  // the file was read; its verdict is negative (docs/cli.md)
    CHECK(r.out.find((dir / "typo.toml").string() + ":2:1: replicate: unknown key (did you mean 'replicates'?)") !=
          std::string::npos);
    fs::remove_all(dir);
}

TEST_CASE("manikin campaigns lists a database's campaigns, status, trial watch and live talk to a running daemon",
          "[cli][campaign]") {
    const auto dir = operator_dir("console");
    const std::string socket = (dir / "d.sock").string(), db = (dir / "d.db").string();
    {
        auto d = DaemonProcess::spawn({std::string(MANIKIND_BIN_DIR) + "/manikind", "--virtual", "--socket", socket, "--database",
                                       db, "--campaign", std::string(MANIKIND_CONFIG_DIR) + "/campaign-example.toml"});
        REQUIRE(d.read_until("control socket"));
        const auto watch = run_manikin("trial watch --once --socket " + socket);
        CHECK(watch.exit_code == 0);
        CHECK(watch.out.find('\033') == std::string::npos);  // stdout is a pipe here
        CHECK(watch.out.find("measured:") != std::string::npos);
        CHECK(watch.out.find("chamber air temp") != std::string::npos);
        const auto live = run_manikin("live --socket " + socket);
        CHECK(live.exit_code == 0);
        CHECK(live.out.find("windsonic/air_speed_m_s") != std::string::npos);
        CHECK(live.out.find("m/s") != std::string::npos);
        const auto live_json = nlohmann::json::parse(run_manikin("live --json --socket " + socket).out);
        CHECK(live_json["manikin/z01.skin_temp_c"]["unit"] == "°C");
        const auto campaigns = nlohmann::json::parse(run_manikin("campaigns --json --db " + db).out);
        REQUIRE(campaigns.size() == 1);
        CHECK(campaigns[0]["name"] == "humid-series-2026-11");
        CHECK(campaigns[0]["trials_total"] == 6);
        const auto table = run_manikin("campaigns --db " + db);
        CHECK(table.exit_code == 0);
        CHECK(table.out.find("humid-series-2026-11") != std::string::npos);
        CHECK(WEXITSTATUS(d.terminate()) == 0);
    }
    CHECK(run_manikin("campaigns --db " + (dir / "none.db").string() + " 2>/dev/null").exit_code == 2);
    fs::remove_all(dir);
}

TEST_CASE("manikin log prints the idle log as CSV for the channels asked, and names a channel that does not exist",
          "[cli][idle]") {
    const auto dir = std::filesystem::temp_directory_path() / ("manikind-test-idle-log-" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    const std::string db = (dir / "d.db").string();
    {
        // Ten virtual minutes with no campaign: the idle log is all there is.
        auto c = manikind::config::default_config();
        c.database = db;
        c.simulation.runtime_dir = (dir / "sim").string();
        c.log_level = "error";
        c.idle_log_period_s = 30.0;
        manikind::LabDaemon d({c, true, 1.0});
        for (int i = 0; i < 600; ++i) d.step_virtual(1.0);
    }
    auto r = manikind::test::run_manikin("log --db " + db + " --channel chamber/air_temp_pv_c");
    REQUIRE(r.exit_code == 0);
    std::size_t lines = 0;
    for (std::size_t p = r.out.find('\n'); p != std::string::npos; p = r.out.find('\n', p + 1)) ++lines;
    CHECK(r.out.rfind("utc_s,channel,value,unit,quality\n", 0) == 0);
    CHECK(lines == 1 + 20);  // the header and one reading per 30 s over 600 s
    CHECK(r.out.find(",chamber/air_temp_pv_c,22,°C,0\n") != std::string::npos);
    r = manikind::test::run_manikin("log --db " + db + " --channel nope/x 2>&1");
    CHECK(r.exit_code != 0);
    CHECK(r.out.find("--channel nope/x: no such channel") != std::string::npos);
    std::filesystem::remove_all(dir);
}
