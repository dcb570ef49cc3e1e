// kill -9 of the daemon mid-trial, then a restart: the trial is marked interrupted with its data
// intact, no committed sample is lost, and the database passes PRAGMA integrity_check.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "daemon/core/recorder/database.hpp"
#include "daemon_process.hpp"

namespace fs = std::filesystem;
using manikind::test::DaemonProcess;

TEST_CASE("kill -9 mid-trial: restart marks the trial interrupted, committed samples intact", "[daemon][crash]") {
    const fs::path dir = fs::temp_directory_path() / ("manikind-crash-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    {
        std::ofstream plan(dir / "plan.toml");
        plan << "name = \"crash\"\nreplicates = 1\ntrial_duration_min = 40\n[[cases]]\nchamber_temp_c = 35\n"
                "chamber_rh_pct = 27\nskin_setpoint_c = 35\nwet = true\n";
    }
    const std::string bin = std::string(MANIKIND_BIN_DIR) + "/manikind";
    const std::string db_path = (dir / "crash.db").string();
    const std::vector<std::string> common = {bin, "--virtual", "--database", db_path, "--socket", (dir / "d.sock").string()};
    auto args = common;
    args.insert(args.end(), {"--campaign", (dir / "plan.toml").string()});
    auto child = DaemonProcess::spawn(args);

    // Read the daemon's progress lines until the trial is acquiring, then kill it without warning.
    REQUIRE(child.read_until("acquiring trial"));
    const std::string& out = child.output();
    const long committed_before_kill = std::stol(out.substr(out.rfind("committed=") + 10));
    REQUIRE(committed_before_kill > 0);
    ::kill(child.pid(), SIGKILL);
    const int status = child.wait();
    CHECK(WIFSIGNALED(status));

    // Restart: the daemon marks what was running as interrupted, then (no campaign) exits.
    auto restart = common;
    restart.push_back("--exit-when-done");
    auto again = DaemonProcess::spawn(restart);
    CHECK(WEXITSTATUS(again.wait()) == 0);

    auto db = manikind::recorder::Database::open(db_path);
    CHECK(db.integrity_check() == "ok");
    const auto id = db.find_campaign("crash");
    REQUIRE(id);
    const auto trials = db.trials(*id);
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "interrupted");
    CHECK(trials[0].reason == "daemon restarted");
    // Every row committed before the kill is in the trial's samples or (before the trial began) the idle log.
    CHECK(db.sample_count(trials[0].id) + db.idle_sample_count() >= committed_before_kill);
    fs::remove_all(dir);
}
