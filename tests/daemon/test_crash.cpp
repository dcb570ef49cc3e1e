// kill -9 of the daemon mid-trial, then a restart: the trial is marked interrupted with its data
// intact, no committed sample is lost, and the database passes PRAGMA integrity_check.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include "analysis/recording.hpp"
#include "store/database.hpp"
#include "store/database_export.hpp"
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
    // The crash ring in the test's directory (it would be /dev/shm), so the restart finds it there.
    {
        std::ofstream config(dir / "lab.toml");
        config << "[recorder]\ncrash_ring_dir = \"" << dir.string() << "\"\n";
    }
    const std::vector<std::string> common = {bin, "--virtual", "--config", (dir / "lab.toml").string(), "--database", db_path,
                                             "--socket", (dir / "d.sock").string()};
    auto args = common;
    args.insert(args.end(), {"--campaign", (dir / "plan.toml").string()});
    auto child = DaemonProcess::spawn(args);

    // Read the daemon's progress lines until the trial is acquiring, then kill it without warning.
    REQUIRE(child.read_until("acquiring trial"));
    const std::string& out = child.output();
    const long committed_before_kill = std::stol(out.substr(out.rfind("committed=") + 10));
    const long accepted_before_kill = std::stol(out.substr(out.rfind("accepted=") + 9));
    REQUIRE(accepted_before_kill > 0);
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
    // On the virtual clock (months ahead of the wall clock here) the trial ends when the
    // recording stopped, never before it began (it took the wall clock's time before issue 60).
    REQUIRE(trials[0].started_utc_ns);
    REQUIRE(trials[0].ended_utc_ns);
    CHECK(*trials[0].ended_utc_ns >= *trials[0].started_utc_ns);
    CHECK(*trials[0].ended_utc_ns - *trials[0].started_utc_ns < 24LL * 3600 * 1'000'000'000);
    // Every row accepted before the kill, committed or not (the crash ring kept the rest), is in
    // the trial's samples or (before the trial began) the idle log.
    CHECK(committed_before_kill <= accepted_before_kill);
    CHECK(db.sample_count(trials[0].id) + db.idle_sample_count() >= accepted_before_kill);
    fs::remove_all(dir);
}

namespace {

struct CrashDir {
    fs::path path;
    explicit CrashDir(const std::string& name)
        : path(fs::temp_directory_path() / ("manikind-" + name + "-" + std::to_string(::getpid()))) {
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~CrashDir() { fs::remove_all(path); }
    void write_plan(const std::string& file, int replicates, double second_case_temp_c) const {
        std::ofstream plan(path / file);
        plan << "name = \"survivor\"\nreplicates = " << replicates
             << "\ntrial_duration_min = 40\n"
                "[[cases]]\nchamber_temp_c = 35\nchamber_rh_pct = 27\nskin_setpoint_c = 35\nwet = false\n"
                "[[cases]]\nchamber_temp_c = "
             << second_case_temp_c << "\nchamber_rh_pct = 25\nskin_setpoint_c = 35\nwet = false\n";
    }
    std::vector<std::string> daemon(const std::string& plan) const {
        return {std::string(MANIKIND_BIN_DIR) + "/manikind", "--virtual", "--database", (path / "c.db").string(),
                "--socket", (path / "d.sock").string(), "--campaign", (path / plan).string(), "--exit-when-done"};
    }
};

}  // namespace

TEST_CASE("kill -9 mid-campaign, the same plan started again: it continues and completes, every trial done once",
          "[daemon][crash][continue]") {
    CrashDir dir("continue");
    dir.write_plan("plan.toml", 1, 38);
    {
        auto child = DaemonProcess::spawn(dir.daemon("plan.toml"));
        // The first trial finishes, the second is acquiring (trial ids count from 1): kill it there.
        REQUIRE(child.read_until("acquiring trial 2 "));
        ::kill(child.pid(), SIGKILL);
        child.wait();
    }
    {
        auto db = manikind::recorder::Database::open(dir.path / "c.db");
        const auto trials = db.trials(db.find_campaign("survivor").value());
        REQUIRE(trials.size() == 2);
        CHECK(trials[0].state == "done");
        CHECK(trials[1].state == "acquiring");  // as the kill left it
    }
    // A changed plan under the same name is refused with the difference named.
    dir.write_plan("changed.toml", 1, 39);
    auto refused = DaemonProcess::spawn(dir.daemon("changed.toml"));
    const int refused_status = refused.wait();
    CHECK(WEXITSTATUS(refused_status) != 0);
    CHECK_THAT(refused.output(), Catch::Contains("chamber_temp_c: was 38") && Catch::Contains("now 39"));

    auto again = DaemonProcess::spawn(dir.daemon("plan.toml"));
    CHECK(WEXITSTATUS(again.wait()) == 0);

    auto db = manikind::recorder::Database::open(dir.path / "c.db");
    const auto events = db.events(std::nullopt);
    CHECK(std::any_of(events.begin(), events.end(), [](const auto& e) {
        return e.kind == "campaign" && e.message == "'survivor' continued: 1 of 2 trials done before, 1 to run";
    }));
    CHECK(db.integrity_check() == "ok");
    const auto campaign_id = db.find_campaign("survivor").value();
    const auto campaigns = db.campaigns();
    CHECK(campaigns.front().state == "done");
    std::map<std::pair<std::int64_t, std::int64_t>, int> done_per_trial;
    int interrupted = 0;
    for (const auto& t : db.trials(campaign_id)) {
        if (t.state == "done") ++done_per_trial[{t.case_id, t.replicate}];
        if (t.state == "interrupted") {
            ++interrupted;
            CHECK(t.reason == "daemon restarted");
        }
    }
    CHECK(interrupted == 1);                 // kept, with its reason
    CHECK(done_per_trial.size() == 2);       // both planned trials
    for (const auto& [key, n] : done_per_trial) CHECK(n == 1);  // each done once
    CHECK(db.latest_result(campaign_id).has_value());
}

TEST_CASE("SIGTERM mid-trial ends the trial and the campaign interrupted at once", "[daemon][crash][continue]") {
    CrashDir dir("sigterm");
    dir.write_plan("plan.toml", 1, 38);
    auto child = DaemonProcess::spawn(dir.daemon("plan.toml"));
    REQUIRE(child.read_until("acquiring trial"));
    ::kill(child.pid(), SIGTERM);
    child.wait();
    auto db = manikind::recorder::Database::open(dir.path / "c.db");
    const auto trials = db.trials(db.find_campaign("survivor").value());
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "interrupted");
    CHECK(trials[0].reason == "daemon stopped");
    CHECK(db.campaigns().front().state == "interrupted");
}

TEST_CASE("kill -9 in a physiological trial: the trial ends interrupted and the campaign started again runs the case "
          "afresh from the zones' own temperatures, with no setpoint jump", "[daemon][crash][continue][physiological]") {
    CrashDir dir("physio");
    {
        std::ofstream plan(dir.path / "plan.toml");
        plan << "name = \"loop\"\nreplicates = 1\n[[cases]]\nchamber_temp_c = 41\nchamber_rh_pct = 20\n"
                "control = \"physiological\"\n[cases.model]\nduration_min = 20\n";
    }
    {
        auto child = DaemonProcess::spawn(dir.daemon("plan.toml"));
        REQUIRE(child.read_until("acquiring trial 1 "));
        ::kill(child.pid(), SIGKILL);
        child.wait();
    }
    auto again = DaemonProcess::spawn(dir.daemon("plan.toml"));
    CHECK(WEXITSTATUS(again.wait()) == 0);
    auto db = manikind::recorder::Database::open(dir.path / "c.db");
    const auto trials = db.trials(db.find_campaign("loop").value());
    REQUIRE(trials.size() == 2);
    CHECK(trials[0].state == "interrupted");
    CHECK(trials[1].state == "done");
    // The re-run's first commanded setpoint of every zone is that zone's own skin temperature
    // (to the skin sensor's noise): the model restarts from preconditioning, nothing jumps.
    const auto campaign = manikind::campaign_from_database(db, "loop");
    const auto& t = campaign.trials.back();
    int zones_checked = 0;
    for (std::size_t c = 0; c < campaign.channels.size(); ++c) {
        const auto& ch = campaign.channels[c];
        if (ch.device != "model" || !ch.name.ends_with(".skin_setpoint_c")) continue;
        const auto zone = static_cast<std::size_t>(std::stoi(ch.name.substr(1, 2)));
        for (std::size_t i = 0; i < t.data.rows(); ++i) {
            if (t.data.channel_quality[c][i] == manikind::analysis::kNoSample) continue;
            // The zone's reading in the same 5-s bin or the one before.
            double skin = t.data.skin_temp_c[zone - 1][i];
            if (!std::isfinite(skin) && i > 0) skin = t.data.skin_temp_c[zone - 1][i - 1];
            CHECK(std::abs(t.data.channel_values[c][i] - skin) < 0.3);
            ++zones_checked;
            break;
        }
    }
    CHECK(zones_checked == 35);
}

TEST_CASE("manikind --sim-air-speed sets the simulated enclosure's air speed without a copied config, and a real lab refuses it",
          "[daemon][clothing]") {
    const fs::path dir = fs::temp_directory_path() / ("manikind-airspeed-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    {
        std::ofstream plan(dir / "plan.toml");
        plan << "name = \"ventilated\"\nreplicates = 1\ntrial_duration_min = 40\n[[cases]]\nchamber_temp_c = 25\n"
                "chamber_rh_pct = 40\nskin_setpoint_c = 35\n";
    }
    const std::string bin = std::string(MANIKIND_BIN_DIR) + "/manikind";
    const std::string db_path = (dir / "v.db").string();
    auto child = DaemonProcess::spawn({bin, "--virtual", "--database", db_path, "--socket", (dir / "d.sock").string(),
                                       "--sim-air-speed", "0.4", "--campaign", (dir / "plan.toml").string(), "--exit-when-done"});
    CHECK(WEXITSTATUS(child.wait()) == 0);
    auto db = manikind::recorder::Database::open_read_only(db_path);
    const auto id = db.find_campaign("ventilated");
    REQUIRE(id);
    const auto trials = db.trials(*id);
    REQUIRE(trials.size() == 1);
    std::optional<std::int64_t> channel;
    for (const auto& ch : db.channels())
        if (ch.device_name == "windsonic" && ch.name == "air_speed_m_s") channel = ch.id;
    REQUIRE(channel);
    double sum = 0.0;
    int n = 0;
    for (const auto& s : db.samples(trials[0].id, *channel))
        if (std::isfinite(s.value)) sum += s.value, ++n;
    REQUIRE(n > 100);
    CHECK(sum / n == Approx(0.4).margin(0.05));  // the WindSonic reads the world's 0.4 m/s

    // A real lab's fans set the air speed: the flag is refused there, naming why.
    auto refused = DaemonProcess::spawn({bin, "--config", MANIKIND_CONFIG_DIR "/real-lab.toml", "--database", (dir / "r.db").string(),
                                         "--socket", (dir / "r.sock").string(), "--sim-air-speed", "0.4"});
    CHECK(WEXITSTATUS(refused.wait()) != 0);
    CHECK_THAT(refused.output(), Catch::Contains("--sim-air-speed needs mode = \"simulated\""));
    fs::remove_all(dir);
}
