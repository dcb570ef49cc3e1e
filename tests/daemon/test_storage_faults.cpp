// Issue 30, item 1: every write the daemon makes (samples, the idle log, new channels, events,
// trial and campaign states, results) goes through the recorder, the database's one writer. A
// lock held by another program (BUSY), a full disk (FULL) or a failing disk (IOERR) injected on
// every one of those paths makes them wait, counted and shown, and never kills the daemon or
// loses what it accepted. FULL and IOERR come from a VFS that fails SQLite's writes as the
// kernel would (faulty_vfs.hpp); BUSY from a second connection holding the write lock.
#include <catch2/catch.hpp>

#include <sqlite3.h>

#include <algorithm>
#include <optional>
#include <string>
#include <vector>

#include "daemon_fixture.hpp"
#include "faulty_vfs.hpp"
#include "store/database.hpp"

using manikind::test::DaemonFixture;
using manikind::test::FaultyVfs;

namespace {

enum class Fault { busy, full, io };

const char* alarm_of(Fault f) {
    switch (f) {
        case Fault::busy: return "database_locked";
        case Fault::full: return "disk_full";
        case Fault::io: return "storage_error";
    }
    return "";
}

// Injects one kind of fault into the database's writes until disarmed.
class Injector {
public:
    Injector(Fault fault, FaultyVfs& vfs, std::filesystem::path db) : fault_(fault), vfs_(vfs), db_(std::move(db)) {}
    ~Injector() { disarm(); }
    void arm() {
        if (fault_ == Fault::busy) {
            REQUIRE(sqlite3_open(db_.c_str(), &holder_) == SQLITE_OK);
            REQUIRE(sqlite3_exec(holder_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK);
        } else {
            vfs_.arm(fault_ == Fault::full ? SQLITE_FULL : SQLITE_IOERR_WRITE);
        }
    }
    void disarm() {
        vfs_.disarm();
        if (holder_) {
            sqlite3_exec(holder_, "ROLLBACK", nullptr, nullptr, nullptr);
            sqlite3_close(holder_);
            holder_ = nullptr;
        }
    }

private:
    Fault fault_;
    FaultyVfs& vfs_;
    std::filesystem::path db_;
    sqlite3* holder_ = nullptr;
};

bool has_alarm(manikind::LabDaemon& d, const std::string& kind) {
    for (const auto& a : d.alarms_json())
        if (a.value("kind", "") == kind) return true;
    return false;
}

std::int64_t channel(manikind::recorder::Database& db, const std::string& device, const std::string& name) {
    for (const auto& ch : db.channels())
        if (ch.device_name == device && ch.name == name) return ch.id;
    return -1;
}

// The largest step between consecutive stored readings of one channel, over a time range.
std::int64_t largest_gap_ns(const std::vector<std::int64_t>& times) {
    std::int64_t gap = 0;
    for (std::size_t i = 1; i < times.size(); ++i) gap = std::max(gap, times[i] - times[i - 1]);
    return gap;
}

void check_nothing_lost(manikind::LabDaemon& d) {
    const auto status = d.status_json();
    CHECK(status["recorder"]["lost_after_retries"] == 0);
    CHECK(status["recorder"]["queue_rows"] == 0);
    CHECK(status["storage"]["readings_waiting"] == 0);
    CHECK(status["storage"]["deferred_writes"] == 0);
    CHECK(status["storage"]["writes_lost"] == 0);
    CHECK(status["storage"]["writes_failed"] == 0);
    CHECK(status["storage"]["locked"] == false);
    CHECK(status["storage"]["io_error"] == false);
}

// The idle daemon's first seconds: every channel is new (added to the database on its first
// reading), the idle log and the start events are written, all while the fault holds.
void idle_under_fault(Fault fault) {
    FaultyVfs vfs;
    DaemonFixture f([](manikind::config::Config& c) {
        c.recorder_lock_timeout_s = 0.005;
        c.idle_log_period_s = 1.0;
        c.recorder_commit_interval_s = 0.05;
    });
    auto& d = f.daemon();
    Injector injector(fault, vfs, f.dir() / "test.db");
    injector.arm();
    const double faulty_s = 20.0;
    for (int i = 0; i < static_cast<int>(faulty_s); ++i) d.step_virtual(1.0);  // would have thrown out of the tick
    d.flush_recorder();  // one more attempt, still refused
    d.step_virtual(1.0);  // the tick reads the recorder's state: alarm
    {
        const auto status = d.status_json();
        if (fault == Fault::busy) CHECK(status["storage"]["locked"] == true);
        if (fault == Fault::io) CHECK(status["storage"]["io_error"] == true);
        if (fault == Fault::full) CHECK(status["storage"]["full"] == true);
        CHECK(status["storage"]["readings_waiting"].get<std::size_t>() + status["recorder"]["queue_rows"].get<std::size_t>() > 0);
        CHECK(has_alarm(d, alarm_of(fault)));
    }
    injector.disarm();
    d.flush_recorder();  // the writer tries again now rather than at its next second of wall time
    for (int i = 0; i < 5; ++i) d.step_virtual(1.0);  // the ticks see storage back: alarm cleared
    d.flush_recorder();
    check_nothing_lost(d);
    CHECK(d.status_json()["recorder"]["dropped"] == 0);
    auto& db = d.db();
    // The chamber's PV: one idle-log reading a second from the very first, through the fault.
    const auto pv = channel(db, "chamber", "air_temp_pv_c");
    REQUIRE(pv > 0);
    std::vector<std::int64_t> times;
    for (const auto& r : db.idle_samples(pv, 0)) times.push_back(r.utc_ns);
    CHECK(times.size() >= static_cast<std::size_t>(faulty_s) + 4);
    CHECK(largest_gap_ns(times) <= 1'500'000'000);
    // Every channel the lab has reached the database, each with its readings.
    CHECK(db.channels().size() > 100);
    // The daemon's start events, written while the fault held, and the alarm's episode.
    bool started = false, alarm_raised = false, alarm_cleared = false;
    for (const auto& e : db.events(std::nullopt)) {
        started = started || (e.kind == "daemon" && e.message.starts_with("started"));
        if (e.kind == alarm_of(fault)) (e.severity == "error" ? alarm_raised : alarm_cleared) = true;
    }
    CHECK(started);
    CHECK(alarm_raised);
    CHECK(alarm_cleared);
    CHECK(vfs.failures() + (fault == Fault::busy ? 1 : 0) > 0);  // the fault was really met
}

// A trial's stages change while the fault holds: its state changes and events wait in order,
// its readings too, and the campaign completes when the fault clears.
void trial_under_fault(Fault fault) {
    FaultyVfs vfs;
    DaemonFixture f([](manikind::config::Config& c) { c.recorder_lock_timeout_s = 0.005; });
    auto& d = f.daemon();
    Injector injector(fault, vfs, f.dir() / "test.db");
    REQUIRE(d.start_campaign(manikind::test::quick_plan("faulty")).empty());
    d.step_virtual(1.0);  // the trial is created
    REQUIRE(d.status_json().contains("trial"));
    injector.arm();
    std::vector<std::string> stages_seen;
    for (int i = 0; i < 4000 && stages_seen.size() < 3; ++i) {
        d.step_virtual(1.0);
        const auto stage = d.status_json()["stage"].get<std::string>();
        if (stages_seen.empty() || stages_seen.back() != stage) stages_seen.push_back(stage);
    }
    CHECK(stages_seen.size() >= 2);  // the trial went on while its writes waited
    CHECK(has_alarm(d, alarm_of(fault)));
    CHECK(d.status_json()["storage"]["deferred_writes"].get<std::size_t>() > 0);
    injector.disarm();
    d.run_virtual();
    check_nothing_lost(d);
    CHECK(d.status_json()["recorder"]["dropped"] == 0);
    auto& db = d.db();
    const auto campaigns = db.campaigns();
    REQUIRE(campaigns.size() == 1);
    CHECK(campaigns.front().state == "done");
    std::vector<std::string> stage_events;
    for (const auto& e : db.events(std::nullopt))
        if (e.kind == "stage") stage_events.push_back(e.message);
    for (const auto& s : stages_seen) CHECK(std::find(stage_events.begin(), stage_events.end(), s) != stage_events.end());
    const auto trials = db.trials(campaigns.front().id);
    REQUIRE(trials.size() == 1);
    CHECK(trials.front().state == "done");
    CHECK(db.latest_result(campaigns.front().id).has_value());
    const auto pv = channel(db, "chamber", "air_temp_pv_c");
    REQUIRE(pv > 0);
    std::vector<std::int64_t> times;
    db.for_each_trial_sample(trials.front().id, [&](const manikind::recorder::SampleRow& r) {
        if (r.channel_id == pv) times.push_back(r.mono_ns);
    });
    CHECK(times.size() > 1000);
    CHECK(largest_gap_ns(times) <= 1'500'000'000);
}

}  // namespace

TEST_CASE("storage faults while idle: new channels, the idle log and events wait through BUSY, FULL and IOERR, none lost",
          "[daemon][storage][faults]") {
    SECTION("BUSY: another program holds the write lock") { idle_under_fault(Fault::busy); }
    SECTION("FULL: the disk is full") { idle_under_fault(Fault::full); }
    SECTION("IOERR: the disk fails writes") { idle_under_fault(Fault::io); }
}

TEST_CASE("storage faults mid-trial: states, events and readings wait through BUSY and IOERR, the campaign completes",
          "[daemon][storage][faults]") {
    SECTION("BUSY") { trial_under_fault(Fault::busy); }
    SECTION("IOERR") { trial_under_fault(Fault::io); }
}

TEST_CASE("a full disk mid-trial (injected): heating stops, the trial ends interrupted, nothing accepted is lost, the "
          "same plan started again completes",
          "[daemon][storage][faults]") {
    FaultyVfs vfs;
    DaemonFixture f([](manikind::config::Config& c) { c.recorder_lock_timeout_s = 0.005; });
    auto& d = f.daemon();
    Injector injector(Fault::full, vfs, f.dir() / "test.db");
    const auto plan = manikind::test::quick_plan("full");
    REQUIRE(d.start_campaign(plan).empty());
    for (int i = 0; i < 600; ++i) d.step_virtual(1.0);  // well into the trial
    injector.arm();
    // The writer meets the full disk at its next commit: a flush asks for one now (wall time
    // would otherwise decide when), and the next tick reads the recorder's state.
    d.flush_recorder();
    for (int i = 0; i < 60 && d.campaign_active(); ++i) d.step_virtual(1.0);
    CHECK_FALSE(d.campaign_active());  // interrupted: no heating that cannot be recorded
    CHECK(has_alarm(d, "disk_full"));
    CHECK_FALSE(d.start_campaign(plan).empty());  // refused while the disk is full, with the reason
    injector.disarm();
    d.flush_recorder();  // the writer tries again now rather than at its next second of wall time
    for (int i = 0; i < 5; ++i) d.step_virtual(1.0);
    d.flush_recorder();
    check_nothing_lost(d);
    auto& db = d.db();
    auto trials = db.trials(*db.find_campaign("full"));
    REQUIRE(trials.size() == 1);
    CHECK(trials.front().state == "interrupted");
    CHECK(trials.front().reason == "disk full");
    REQUIRE(d.start_campaign(plan).empty());  // continued
    d.run_virtual();
    trials = d.db().trials(*d.db().find_campaign("full"));
    REQUIRE(trials.size() == 2);
    CHECK(trials.back().state == "done");
}
