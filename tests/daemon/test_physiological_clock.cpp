// Issue 64: the physiological loop on every clock. The real daemon on the simulated lab in real
// time at --speed 10 ticks every 10 lab-seconds; the loop used to take each of those gaps for a
// pause and never left preconditioning. Here a short physiological trial must precondition, start
// its model and advance the model's clock with the lab's; and a pause asked through the API must
// still stop it (on the virtual clock, in process).
#include <catch2/catch.hpp>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>

#include "daemon/campaign_plan.hpp"
#include "daemon/control_client.hpp"
#include "daemon_fixture.hpp"
#include "daemon_process.hpp"

namespace fs = std::filesystem;
using manikind::test::DaemonProcess;

namespace {

// A bound on the whole run, not a verdict: a daemon that never gets where the test waits (the
// loop stuck in preconditioning) is killed after this, which ends its output and fails the wait
// instead of hanging the suite. The run takes about 40 s of wall time at --speed 10.
class KillAfter {
public:
    KillAfter(pid_t pid, std::chrono::seconds limit)
        : thread_([this, pid, limit] {
              std::unique_lock lk(m_);
              if (!cv_.wait_for(lk, limit, [this] { return disarmed_; })) ::kill(pid, SIGKILL);
          }) {}
    ~KillAfter() {
        {
            std::lock_guard lk(m_);
            disarmed_ = true;
        }
        cv_.notify_all();
        thread_.join();
    }

private:
    std::mutex m_;
    std::condition_variable cv_;
    bool disarmed_ = false;
    std::thread thread_;
};

struct ClockDir {
    fs::path path = fs::temp_directory_path() / ("manikind-physio-clock-" + std::to_string(::getpid()));
    ClockDir() {
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~ClockDir() { fs::remove_all(path); }
};

}  // namespace

TEST_CASE("physiological trial on the real clock at --speed 10: preconditioning ends and the model's clock advances "
          "with the lab's", "[daemon][physiological][clock][proof]") {
    ClockDir dir;
    {
        // Debug: the loop's info events ("the model starts", a protocol phase) reach the output.
        // A fast setpoint rate keeps the preconditioning (22 °C zones to the model's ~34.8 °C) short.
        std::ofstream config(dir.path / "lab.toml");
        config << "[logging]\nlevel = \"debug\"\n[recorder]\ncrash_ring_dir = \"" << dir.path.string()
               << "\"\n[physiological]\nmax_setpoint_rate_c_min = 10\n";
        // The enclosure as the simulated lab starts it (22 °C, 40 %), so it settles at once; a
        // protocol phase 1 min into the model says in the output that the model's clock got there.
        std::ofstream plan(dir.path / "plan.toml");
        plan << "name = \"clock\"\nreplicates = 1\nsettle_window_min = 0\n[[cases]]\nchamber_temp_c = 22\n"
                "chamber_rh_pct = 40\ncontrol = \"physiological\"\n[cases.model]\nduration_min = 5\n"
                "[[cases.model.phases]]\nafter_min = 1\nchamber_temp_c = 22\nchamber_rh_pct = 40\n";
    }
    const fs::path socket = dir.path / "d.sock";
    auto child = DaemonProcess::spawn({std::string(MANIKIND_BIN_DIR) + "/manikind", "--config",
                                       (dir.path / "lab.toml").string(), "--database", (dir.path / "c.db").string(),
                                       "--socket", socket.string(), "--speed", "10", "--campaign",
                                       (dir.path / "plan.toml").string()});
    REQUIRE(child.started());
    KillAfter bound(child.pid(), std::chrono::seconds(240));
    REQUIRE(child.read_until("control socket"));
    CHECK_THAT(child.output(), Catch::Contains("simulated lab, real clock x10;"));
    INFO(child.output());
    const bool started = child.read_until("physiological trial: the model starts");
    INFO(child.output());
    REQUIRE(started);  // before the fix: "preconditioning, model time 0.0" for ever
    const bool phase = child.read_until("the protocol's next phase at 1 min");
    INFO(child.output());
    REQUIRE(phase);
    const auto reply = manikind::call_daemon(socket, {{"cmd", "status"}, {"token", manikind::read_token_file(socket)}});
    REQUIRE(reply.at("ok") == true);
    const auto& status = reply.at("status");
    CHECK(status.at("clock") == "paced");
    const auto& model = status.at("trial").at("model");
    CHECK(model.at("phase") == "running");
    CHECK(model.at("model_time_s").get<double>() >= 60.0);
    CHECK(child.output().find("fell back") == std::string::npos);
    CHECK(child.terminate() == 0);
}

TEST_CASE("physiological trial on the virtual clock: a pause asked through the daemon stops the model's clock and "
          "it goes on from there on resume", "[daemon][physiological][clock]") {
    manikind::test::DaemonFixture f([](manikind::config::Config& c) { c.physiological.max_setpoint_rate_c_min = 10; });
    auto plan = manikind::parse_campaign_plan(
        "name = \"pause\"\nreplicates = 1\nsettle_window_min = 0\n[[cases]]\nchamber_temp_c = 22\nchamber_rh_pct = 40\n"
        "control = \"physiological\"\n[cases.model]\nduration_min = 30\n",
        "pause.toml");
    REQUIRE(f.daemon().start_campaign(plan).empty());
    auto model = [&] {
        const auto s = f.daemon().status_json();
        return s.contains("trial") && s["trial"].contains("model") ? s["trial"]["model"] : nlohmann::json();
    };
    for (int t = 0; t < 3 * 3600; ++t) {
        f.daemon().step_virtual(1.0);
        if (const auto m = model(); !m.is_null() && m.at("model_time_s").get<double>() >= 120.0) break;
    }
    REQUIRE(model().at("phase") == "running");
    const double before_s = model()["model_time_s"].get<double>();
    REQUIRE(f.daemon().pause().empty());
    for (int t = 0; t < 600; ++t) f.daemon().step_virtual(1.0);  // 10 min paused
    CHECK(model()["model_time_s"].get<double>() == before_s);
    REQUIRE(f.daemon().resume().empty());
    for (int t = 0; t < 60; ++t) f.daemon().step_virtual(1.0);
    // A minute on: the model went on by about a minute, not by the 10 min paused.
    const double after_s = model()["model_time_s"].get<double>();
    CHECK(after_s > before_s + 30.0);
    CHECK(after_s <= before_s + 60.0 + manikind::config::PhysiologicalConfig{}.coupling_period_s + 1.0);
    CHECK(model()["phase"] == "running");
}
