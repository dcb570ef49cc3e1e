// Issue 30: a database locked by another program past the busy timeout made the daemon's own
// writes throw StorageBusy out of its thread (terminate: recording and control gone). Now the
// writes wait in order, an alarm says so, and everything is written once the lock is released.
#include <catch2/catch.hpp>

#include <sqlite3.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include "daemon_fixture.hpp"
#include "store/database.hpp"

using manikind::test::DaemonFixture;

namespace {

// Another program holding the database's write lock (BEGIN IMMEDIATE) until released.
class LockHolder {
public:
    explicit LockHolder(const std::filesystem::path& db) {
        REQUIRE(sqlite3_open(db.c_str(), &db_) == SQLITE_OK);
        REQUIRE(sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK);
    }
    void release() {
        if (db_) sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr), sqlite3_close(db_);
        db_ = nullptr;
    }
    ~LockHolder() { release(); }

private:
    sqlite3* db_ = nullptr;
};

}  // namespace

TEST_CASE("storage: a database locked by another program makes the daemon's writes wait, never lost, never fatal",
          "[daemon][storage][busy]") {
    // A short wait for the lock, so that the writer meets it within the test's few seconds.
    DaemonFixture f([](manikind::config::Config& c) { c.recorder_lock_timeout_s = 0.005; });
    auto& d = f.daemon();
    REQUIRE(d.start_campaign(manikind::test::quick_plan("locked")).empty());
    d.step_virtual(1.0);  // the trial is created and configured
    REQUIRE(d.status_json().contains("trial"));
    std::vector<std::string> stages_seen;
    {
        LockHolder other(f.dir() / "test.db");
        // Chamber settling, then the manikin's start and acquiring: stage changes to write.
        for (int i = 0; i < 4000 && stages_seen.size() < 3; ++i) {
            d.step_virtual(1.0);  // would have thrown StorageBusy out of the tick before
            const auto stage = d.status_json()["stage"].get<std::string>();
            if (stages_seen.empty() || stages_seen.back() != stage) stages_seen.push_back(stage);
        }
        const auto status = d.status_json();
        CHECK(status["storage"]["locked"] == true);
        CHECK(status["storage"]["deferred_writes"].get<std::size_t>() > 0);
        CHECK(status["storage"]["busy_waits"].get<std::uint64_t>() > 0);
        bool alarm = false;
        for (const auto& a : d.alarms_json()) alarm = alarm || a.value("kind", "") == "database_locked";
        CHECK(alarm);
        CHECK(stages_seen.size() >= 2);  // the trial went on while its writes waited
    }
    d.run_virtual();  // the lock is gone: the waiting writes are made in order, the campaign ends
    const auto status = d.status_json();
    CHECK(status["storage"]["locked"] == false);
    CHECK(status["storage"]["deferred_writes"] == 0);
    CHECK(status["storage"]["readings_waiting"] == 0);
    CHECK(status["recorder"]["dropped"] == 0);
    auto db = manikind::recorder::Database::open_read_only(f.dir() / "test.db");
    const auto campaigns = db.campaigns();
    REQUIRE(campaigns.size() == 1);
    CHECK(campaigns.front().state == "done");
    // Every stage the daemon went through while locked reached the events table, in order.
    std::vector<std::string> stage_events;
    bool locked_event = false, free_event = false;
    for (const auto& e : db.events(std::nullopt)) {
        if (e.kind == "stage") stage_events.push_back(e.message);
        if (e.kind == "database_locked") (e.severity == "error" ? locked_event : free_event) = true;
    }
    CHECK(locked_event);
    CHECK(free_event);
    for (const auto& s : stages_seen) CHECK(std::find(stage_events.begin(), stage_events.end(), s) != stage_events.end());
    // Every reading of the trial stored, through the locked stretch too: the chamber's PV, polled
    // each second of virtual time, has no gap.
    std::int64_t pv = -1;
    for (const auto& ch : db.channels())
        if (ch.device_name == "chamber" && ch.name == "air_temp_pv_c") pv = ch.id;
    REQUIRE(pv > 0);
    const auto trials = db.trials(campaigns.front().id);
    REQUIRE(trials.size() == 1);
    std::int64_t previous = -1, largest_gap_ns = 0, readings = 0;
    db.for_each_trial_sample(trials.front().id, [&](const manikind::recorder::SampleRow& r) {
        if (r.channel_id != pv) return;
        if (previous >= 0) largest_gap_ns = std::max(largest_gap_ns, r.mono_ns - previous);
        previous = r.mono_ns;
        ++readings;
    });
    CHECK(readings > 1000);
    CHECK(largest_gap_ns <= 1'500'000'000);
}
