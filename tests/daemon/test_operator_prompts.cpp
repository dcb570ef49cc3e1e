// Operator prompts on the real clock (issue 64 part 2): a clothing campaign run by the real daemon
// at --speed 10 waits at the dressing until `manikin continue`, as a lab's operator would answer.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "daemon_process.hpp"

namespace fs = std::filesystem;
using manikind::test::DaemonProcess;

TEST_CASE("a clothing campaign on the real clock at --speed 10 waits at the dressing until manikin continue",
          "[daemon][clothing][operator]") {
    const fs::path dir = fs::temp_directory_path() / ("manikind-prompt-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    {
        std::ofstream plan(dir / "plan.toml");
        plan << "name = \"dressing\"\nreplicates = 1\ntrial_duration_min = 40\n[ensembles.coverall]\n"
                "description = \"cotton coverall\"\n[[cases]]\nid = 1\nchamber_temp_c = 20\nchamber_rh_pct = 50\n"
                "enclosure_temp_c = 20\nenclosure_rh_pct = 50\nskin_setpoint_c = 35\nensemble = \"coverall\"\ntest = \"insulation\"\n";
        std::ofstream lab(dir / "lab.toml");
        lab << "[simulation]\noperator_prompts = \"wait\"\n[logging]\nlevel = \"debug\"  # the stage events on stdout\n";
    }
    const std::string bin = std::string(MANIKIND_BIN_DIR);
    const std::string sock = (dir / "d.sock").string();
    auto daemon = DaemonProcess::spawn({bin + "/manikind", "--speed", "10", "--config", (dir / "lab.toml").string(), "--database",
                                        (dir / "c.db").string(), "--socket", sock, "--campaign", (dir / "plan.toml").string()});
    REQUIRE(daemon.read_until("waiting for the operator: dress the manikin in 'coverall'"));
    // manikin status names the wait; the trial stays in configuring however long nobody answers.
    auto status = DaemonProcess::spawn({bin + "/manikin", "status", "--socket", sock});
    CHECK(WEXITSTATUS(status.wait()) == 0);
    CHECK_THAT(status.output(), Catch::Contains("WAITING FOR THE OPERATOR: dress the manikin in 'coverall' for the insulation test") &&
                                    Catch::Contains("stage configuring"));
    auto go = DaemonProcess::spawn({bin + "/manikin", "continue", "--socket", sock});
    CHECK(WEXITSTATUS(go.wait()) == 0);
    CHECK_THAT(go.output(), Catch::Contains("continued: dress the manikin in 'coverall'"));
    // The trial goes on to chamber settling, and the answer is in the log with who gave it.
    CHECK(daemon.read_until("waiting for the enclosure"));
    CHECK_THAT(daemon.output(), Catch::Contains("done: dress the manikin in 'coverall'"));
    auto again = DaemonProcess::spawn({bin + "/manikin", "continue", "--socket", sock});
    CHECK(WEXITSTATUS(again.wait()) == 4);  // nothing waits now: refused
    CHECK_THAT(again.output(), Catch::Contains("nothing is waiting for the operator"));
    ::kill(daemon.pid(), SIGTERM);
    daemon.wait();
    fs::remove_all(dir);
}
