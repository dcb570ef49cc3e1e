#include <catch2/catch.hpp>

#include <signal.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <random>
#include <sstream>
#include <span>
#include <string>
#include <thread>

#include <fmt/core.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include "store/crash_ring.hpp"
#include "store/database.hpp"
#include "store/recorder.hpp"
#include "base/user_error.hpp"

using namespace manikind;
using namespace manikind::recorder;
namespace fs = std::filesystem;

namespace {

// A fresh directory per test, removed at the end whatever happens.
struct TempDir {
    fs::path path;
    explicit TempDir(const std::string& name) {
        static std::atomic<int> counter{0};
        path = fs::temp_directory_path() / fmt::format("manikind-test-recorder-{}-{}-{}", name, ::getpid(), counter++);
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
};

// Raw SQLite, to build files the Database class would never write.
void raw_exec(const fs::path& path, const std::string& sql) {
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &db) == SQLITE_OK);
    char* error = nullptr;
    const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error);
    const std::string message = error ? error : "";
    sqlite3_free(error);
    sqlite3_close(db);
    INFO(message);
    REQUIRE(rc == SQLITE_OK);
}

struct Fixture {
    std::int64_t campaign = 0, case_id = 0, trial = 0, channel_a = 0, channel_b = 0;
};

Fixture make_fixture(Database& db) {
    Fixture f;
    f.campaign = db.create_campaign("paper-2024", R"({"cases":1})");
    f.case_id = db.add_case(f.campaign, "T20-RH50", R"({"t_air_c":20,"rh_pct":50})", 0);
    f.trial = db.create_trial(f.campaign, f.case_id, 1);
    const auto device = db.device_id("manikin", "newton-34", "can0");
    f.channel_a = db.channel_id(device, "zone01.heat_flux", "W/m2");
    f.channel_b = db.channel_id(device, "zone01.skin_temp", "degC");
    return f;
}

// A file with the fixture's rows, its connection closed again (before a fork(), or so that
// the Recorder under test is the only writer), in `journal` mode, its one trial `trial_state`.
Fixture fixture_file(const fs::path& path, Journal journal = Journal::wal, Durability durability = Durability::process,
                     const std::string& trial_state = "pending") {
    auto db = Database::open(path, durability, journal);
    const Fixture f = make_fixture(db);
    if (trial_state != "pending") db.set_trial_state(f.trial, trial_state, "", 1);
    return f;
}

const char* journal_name(Journal journal) { return journal == Journal::wal ? "WAL" : "rollback journal"; }

// A recording child process: `body(report)` runs in it, `report(n)` sends a count to the
// parent (false once the parent has gone), and the child never returns into Catch (a throw
// exits 1). The parent reads the counts with next() and kills the child when it likes.
class RecordingChild {
public:
    using Report = std::function<bool(std::uint64_t)>;
    explicit RecordingChild(const std::function<void(const Report&)>& body) {
        int fds[2];
        REQUIRE(::pipe(fds) == 0);
        pid_ = ::fork();
        REQUIRE(pid_ >= 0);
        if (pid_ == 0) {
            ::close(fds[0]);
            int status = 0;
            try {
                body([&](std::uint64_t n) { return ::write(fds[1], &n, sizeof n) == static_cast<ssize_t>(sizeof n); });
            } catch (...) {
                status = 1;
            }
            ::_exit(status);
        }
        ::close(fds[1]);
        read_fd_ = fds[0];
    }
    RecordingChild(const RecordingChild&) = delete;
    RecordingChild& operator=(const RecordingChild&) = delete;
    ~RecordingChild() {
        kill();
        ::close(read_fd_);
    }
    std::optional<std::uint64_t> next() {
        std::uint64_t n = 0;
        if (::read(read_fd_, &n, sizeof n) != static_cast<ssize_t>(sizeof n)) return std::nullopt;
        return n;
    }
    pid_t pid() const { return pid_; }
    // SIGKILL and reap (once); the wait status.
    int kill() {
        if (!reaped_) {
            ::kill(pid_, SIGKILL);
            ::waitpid(pid_, &status_, 0);
            reaped_ = true;
        }
        return status_;
    }

private:
    pid_t pid_ = -1;
    int read_fd_ = -1;
    int status_ = 0;
    bool reaped_ = false;
};

}  // namespace

TEST_CASE("database: a fresh file is at the latest schema, in WAL mode and sound", "[recorder]") {
    TempDir dir("fresh");
    auto db = Database::open(dir.path / "trials.db");
    CHECK(db.schema_version() == Database::latest_schema_version());
    CHECK(Database::latest_schema_version() == static_cast<int>(Database::migrations().size()));
    CHECK(db.journal_mode() == "wal");
    CHECK(db.integrity_check() == "ok");
    // Reopening an up-to-date file changes nothing.
    auto again = Database::open(dir.path / "trials.db");
    CHECK(again.schema_version() == Database::latest_schema_version());
}

TEST_CASE("database: SQLite keeps no allocation counters (their process-wide lock was 6 % of the demo), set before main",
          "[recorder]") {
    // With SQLITE_CONFIG_MEMSTATUS on (SQLite's default) every allocation takes a global mutex to
    // keep sqlite3_memory_used(); off, that count stays 0 however much is allocated. The store
    // sets it before main, so no order of tests (or a raw sqlite3_open first) can undo it.
    TempDir dir("memstatus");
    auto db = Database::open(dir.path / "trials.db");
    const auto f = make_fixture(db);
    std::vector<SampleRow> rows;
    for (std::int64_t i = 0; i < 2000; ++i) rows.push_back({f.trial, f.channel_a, i, i, static_cast<double>(i), 0});
    CHECK(db.insert_samples(rows) == 0);
    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open_v2((dir.path / "trials.db").c_str(), &raw, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    CHECK(sqlite3_exec(raw, "SELECT count(*) FROM samples", nullptr, nullptr, nullptr) == SQLITE_OK);
    sqlite3_close(raw);
    CHECK(sqlite3_memory_used() == 0);
}

TEST_CASE("database: the lab notebook is append-only: notes are stored by time, and the file refuses an edit or a deletion",
          "[recorder][notes]") {
    TempDir dir("notes");
    auto db = Database::open(dir.path / "trials.db");
    const auto f = make_fixture(db);
    db.add_note({0, f.campaign, std::nullopt, 2000, "ana", "operator", "Ana ran it"});
    db.add_note({0, f.campaign, f.trial, 1000, "bo", "garment", "sleeve torn at zone 12"});
    const auto notes = db.notes(f.campaign);
    REQUIRE(notes.size() == 2);
    CHECK(notes[0].utc_ns == 1000);  // by time, not by insertion
    CHECK(notes[0].trial_id == f.trial);
    CHECK(notes[1].author == "ana");
    CHECK_FALSE(notes[1].trial_id.has_value());
    // A kind outside the four and a note on no campaign are refused by the schema itself.
    CHECK_THROWS(db.add_note({0, f.campaign, std::nullopt, 3000, "ana", "gossip", "x"}));
    CHECK_THROWS(db.add_note({0, 424242, std::nullopt, 3000, "ana", "comment", "x"}));
    // Another program (sqlite3 on the file) cannot edit or delete one.
    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open((dir.path / "trials.db").c_str(), &raw) == SQLITE_OK);
    char* err = nullptr;
    CHECK(sqlite3_exec(raw, "UPDATE notes SET text = 'nothing happened'", nullptr, nullptr, &err) != SQLITE_OK);
    REQUIRE(err != nullptr);
    CHECK(std::string(err).find("append-only") != std::string::npos);
    sqlite3_free(err);
    err = nullptr;
    CHECK(sqlite3_exec(raw, "DELETE FROM notes", nullptr, nullptr, &err) != SQLITE_OK);
    sqlite3_free(err);
    sqlite3_close(raw);
    CHECK(db.notes(f.campaign).size() == 2);
    CHECK(db.notes(f.campaign)[0].text == "sleeve torn at zone 12");
}

TEST_CASE("database: [recorder] durability picks SQLite's sync level, from the configuration to the daemon's connections",
          "[recorder][durability]") {
    TempDir dir("durability");
    CHECK(Database::open(dir.path / "a.db").synchronous() == 1);                                 // NORMAL
    CHECK(Database::open(dir.path / "b.db", manikind::recorder::Durability::power).synchronous() == 2);  // FULL
}

// The file's own record of its journal: header bytes 18 and 19 are 2 in WAL mode, 1 otherwise.
int header_journal_byte(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::array<char, 20> header{};
    in.read(header.data(), header.size());
    return in ? header[18] : -1;
}

TEST_CASE("database: [recorder] journal = rollback puts the file in rollback mode, and a reader never switches it back",
          "[recorder][journal]") {
    TempDir dir("journal");
    const auto path = dir.path / "trials.db";
    Fixture f;
    {
        auto db = Database::open(path, Durability::process, Journal::rollback);
        CHECK(db.journal_mode() == "truncate");
        f = make_fixture(db);
        db.insert_samples(std::vector<SampleRow>{{f.trial, f.channel_a, 1000, 1000, 1.0, 0}});
        CHECK_FALSE(fs::exists(path.string() + "-wal"));
    }
    CHECK(header_journal_byte(path) == 1);
    {
        // A reader (manikin export, campaigns, the console) keeps the daemon's choice, here
        // while the daemon's connection is open: an idle one could not stop a switch to WAL.
        auto daemon = Database::open(path, Durability::process, Journal::rollback);
        auto reader = Database::open(path);
        CHECK(reader.journal_mode() == "truncate");
        CHECK(reader.sample_count(f.trial) == 1);
        daemon.insert_samples(std::vector<SampleRow>{{f.trial, f.channel_a, 2000, 2000, 2.0, 0}});
        CHECK(reader.sample_count(f.trial) == 2);
    }
    CHECK(header_journal_byte(path) == 1);
    // Back to WAL when asked, and a WAL file stays WAL for a reader.
    CHECK(Database::open(path, Durability::process, Journal::wal).journal_mode() == "wal");
    CHECK(header_journal_byte(path) == 2);
    CHECK(Database::open(path).journal_mode() == "wal");
    {
        // Leaving WAL needs the file to itself: with another connection open it stays WAL, at once.
        // (No wall-clock bound here: a loaded machine must not fail a correct program.)
        auto other = Database::open(path);
        auto db = Database::open(path, Durability::process, Journal::rollback);
        CHECK(db.journal_mode() == "wal");
        CHECK(db.sample_count(f.trial) == 2);
    }
    CHECK(Database::open(path, Durability::process, Journal::rollback).journal_mode() == "truncate");
    // A new file is WAL unless told.
    CHECK(Database::open(dir.path / "new.db").journal_mode() == "wal");
}

TEST_CASE("database: a version 1 file is upgraded and a newer one is refused", "[recorder]") {
    TempDir dir("migrate");
    const auto v1 = dir.path / "v1.db";
    raw_exec(v1, std::string(Database::migrations()[0]) + "PRAGMA user_version = 1;");
    raw_exec(v1, "INSERT INTO campaigns (name, definition_json, created_utc_ns) VALUES ('old', '{}', 1)");
    {
        auto db = Database::open(v1);
        CHECK(db.schema_version() == Database::latest_schema_version());
        CHECK(db.find_campaign("old").has_value());  // data survives the upgrade
        CHECK(db.integrity_check() == "ok");
    }
    // Version 2's index is really there.
    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open(v1.c_str(), &raw) == SQLITE_OK);
    sqlite3_stmt* s = nullptr;
    REQUIRE(sqlite3_prepare_v2(raw, "SELECT count(*) FROM sqlite_master WHERE type = 'index' AND name = 'events_by_trial_time'",
                               -1, &s, nullptr) == SQLITE_OK);
    REQUIRE(sqlite3_step(s) == SQLITE_ROW);
    CHECK(sqlite3_column_int(s, 0) == 1);
    sqlite3_finalize(s);
    sqlite3_close(raw);

    const auto future = dir.path / "future.db";
    raw_exec(future, "PRAGMA user_version = 999");
    CHECK_THROWS_WITH(Database::open(future),
                      Catch::Contains(future.string()) && Catch::Contains("999") && Catch::Contains("newer"));

    const auto junk = dir.path / "junk.db";
    std::ofstream(junk) << "this is a CSV file, not a database\n1,2,3\n";
    CHECK_THROWS_WITH(Database::open(junk), Catch::Contains(junk.string()) && Catch::Contains("not a database"));
    CHECK_THROWS_AS(Database::open(dir.path / "no-such-dir" / "x.db"), UserError);
}

TEST_CASE("database: campaigns, cases, trials, channels, events and results round-trip", "[recorder]") {
    TempDir dir("roundtrip");
    auto db = Database::open(dir.path / "trials.db");
    const auto f = make_fixture(db);

    CHECK(db.find_campaign("paper-2024") == f.campaign);
    CHECK_FALSE(db.find_campaign("nope").has_value());
    CHECK_THROWS_WITH(db.create_campaign("paper-2024", "{}"), Catch::Contains("already exists") &&
                                                                  Catch::Contains("trials.db"));
    db.set_campaign_state(f.campaign, "running");
    const auto campaigns = db.campaigns();
    REQUIRE(campaigns.size() == 1);
    CHECK(campaigns[0].definition_json == R"({"cases":1})");
    CHECK(campaigns[0].state == "running");
    CHECK(campaigns[0].created_utc_ns > 0);

    db.add_case(f.campaign, "T30-RH30", "{}", -1);
    const auto cases = db.cases(f.campaign);
    REQUIRE(cases.size() == 2);
    CHECK(cases[0].name == "T30-RH30");  // ordered by position
    CHECK(cases[1].conditions_json == R"({"t_air_c":20,"rh_pct":50})");

    auto t = db.trial(f.trial);
    REQUIRE(t);
    CHECK(t->state == "pending");
    CHECK_FALSE(t->started_utc_ns);
    db.set_trial_state(f.trial, "acquiring", "", 1000);
    db.set_trial_steady(f.trial, 5'000'000'000);
    db.add_trial_flag(f.trial, 0b01);
    db.add_trial_flag(f.trial, 0b100);
    db.set_trial_state(f.trial, "done", "completed", 2000);
    t = db.trial(f.trial);
    CHECK(t->state == "done");
    CHECK(t->reason == "completed");
    CHECK(t->started_utc_ns == 1000);
    CHECK(t->ended_utc_ns == 2000);
    CHECK(t->steady_from_mono_ns == 5'000'000'000);
    CHECK(t->quality_flags == 0b101);
    CHECK(db.trials(f.campaign).size() == 1);
    CHECK_FALSE(db.trial(9999));
    CHECK_THROWS_AS(db.set_trial_state(9999, "done", "", 0), UserError);

    // Get-or-create: same ids again; a changed unit is refused.
    const auto device = db.device_id("manikin", "newton-34", "can1");
    CHECK(db.channel_id(device, "zone01.heat_flux", "W/m2") == f.channel_a);
    CHECK_THROWS_WITH(db.channel_id(device, "zone01.heat_flux", "W"), Catch::Contains("W/m2"));
    const auto channels = db.channels();
    REQUIRE(channels.size() == 2);
    CHECK(channels[0].device_name == "manikin");
    CHECK(channels[0].unit == "W/m2");

    db.add_event(f.trial, 20, 200, "warn", "comm", "zone 3 timeout");
    db.add_event(std::nullopt, 10, 100, "info", "daemon", "started");
    CHECK(db.events(std::nullopt).size() == 2);
    const auto trial_events = db.events(f.trial);
    REQUIRE(trial_events.size() == 1);
    CHECK(trial_events[0].message == "zone 3 timeout");
    CHECK(db.events(std::nullopt)[0].kind == "daemon");  // ordered by mono_ns
    CHECK_FALSE(db.events(std::nullopt)[0].trial_id);

    CHECK_FALSE(db.latest_result(f.campaign));
    db.store_result(f.campaign, R"({"v":1})", 10);
    db.store_result(f.campaign, R"({"v":2})", 20);
    CHECK(db.latest_result(f.campaign)->json == R"({"v":2})");

    const auto id = db.store_twin_version("reconciled", 1, "name = \"reconciled\"\n");
    CHECK(db.store_twin_version("reconciled", 1, "name = \"reconciled\"\n") == id);
    CHECK_THROWS_AS(db.store_twin_version("reconciled", 1, "name = \"other\"\n"), UserError);
    CHECK(db.twin_version_toml("reconciled", 1) == "name = \"reconciled\"\n");

    const SampleRow rows[] = {{f.trial, f.channel_a, 2, 20, std::numeric_limits<double>::quiet_NaN(), 3},
                              {f.trial, f.channel_a, 1, 10, 42.5, 0}};
    CHECK(db.insert_samples(rows) == 0);
    CHECK(db.insert_samples(std::span<const SampleRow>(rows, 1)) == 1);  // same trial, channel and time: kept once
    const auto back = db.samples(f.trial, f.channel_a);
    REQUIRE(back.size() == 2);
    CHECK(back[0].value == 42.5);
    CHECK(std::isnan(back[1].value));
    CHECK(back[1].quality == 3);
    CHECK(db.sample_count(f.trial) == 2);
    CHECK(db.integrity_check() == "ok");
}

TEST_CASE("database: upgrading an existing file is logged step by step, creating a new one is not", "[recorder]") {
    TempDir dir("upgrade-log");
    std::ostringstream log;
    const auto previous = spdlog::default_logger();
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("capture", std::make_shared<spdlog::sinks::ostream_sink_mt>(log)));
    const auto restore = [&] { spdlog::set_default_logger(previous); };
    try {
        Database::open(dir.path / "new.db");
        const std::string created = log.str();
        std::string v4;
        for (int i = 0; i < 4; ++i) v4 += Database::migrations()[static_cast<std::size_t>(i)];
        raw_exec(dir.path / "v4.db", v4 + "PRAGMA user_version = 4;");
        Database::open(dir.path / "v4.db");
        restore();
        CHECK(created.find("upgrading") == std::string::npos);
        CHECK_THAT(log.str(), Catch::Contains("v4.db: upgrading the database schema from version 4 to 5"));
        CHECK_THAT(log.str(), Catch::Contains("from version 7 to 8"));
    } catch (...) {
        restore();
        throw;
    }
}

TEST_CASE("database: a version 4 file's samples and idle log survive the move to the time-major key (v5), and its trials get UUIDs (v6)", "[recorder]") {
    TempDir dir("v4");
    const auto path = dir.path / "v4.db";
    std::string v4;
    for (int i = 0; i < 4; ++i) v4 += Database::migrations()[static_cast<std::size_t>(i)];
    raw_exec(path, v4 + "PRAGMA user_version = 4;");
    raw_exec(path,
             "INSERT INTO campaigns (name, definition_json, created_utc_ns) VALUES ('old', '{}', 1);"
             "INSERT INTO cases (campaign_id, name, conditions_json, position) VALUES (1, 'c', '{}', 0);"
             "INSERT INTO trials (campaign_id, case_id, replicate) VALUES (1, 1, 1);"
             "INSERT INTO devices (name, kind, address) VALUES ('manikin', 'm', 'can0');"
             "INSERT INTO channels (device_id, name, unit) VALUES (1, 'a', 'W/m2'), (1, 'b', 'degC');"
             // Stored channel-major, as version 4 keyed them: b's rows come before a's later ones.
             "INSERT INTO samples VALUES (1, 1, 10, 110, 1.0, 0), (1, 1, 20, 120, 2.0, 0), (1, 2, 10, 110, 3.0, 0),"
             " (1, 2, 20, 120, NULL, 3);"
             "INSERT INTO idle_samples VALUES (2, 500, 5, 7.0, 0), (1, 500, 5, 8.0, 0), (1, 400, 4, 9.0, 0);"
             "INSERT INTO events (trial_id, mono_ns, utc_ns, severity, kind, message) VALUES (1, 5, 105, 'info', 'stage', 'acquiring');");
    auto db = Database::open(path);
    CHECK(db.schema_version() == Database::latest_schema_version());
    CHECK(db.integrity_check() == "ok");
    CHECK(db.sample_count(1) == 4);
    std::vector<std::pair<std::int64_t, std::int64_t>> order;  // (mono_ns, channel) as read back
    db.for_each_trial_sample(1, [&](const SampleRow& r) { order.emplace_back(r.mono_ns, r.channel_id); });
    CHECK(order == std::vector<std::pair<std::int64_t, std::int64_t>>{{10, 1}, {10, 2}, {20, 1}, {20, 2}});
    const auto b = db.samples(1, 2);
    REQUIRE(b.size() == 2);
    CHECK(b[0].value == 3.0);
    CHECK(std::isnan(b[1].value));
    CHECK(b[1].quality == 3);
    const auto idle = db.idle_samples(1, 0);
    REQUIRE(idle.size() == 2);
    CHECK(idle[0].utc_ns == 400);
    CHECK(idle[1].value == 8.0);
    CHECK(db.newest_idle_utc_ns() == 500);
    // Version 6 named the old trial, and a new one gets a different name.
    const auto old_uuid = db.trial(1)->uuid;
    CHECK(old_uuid.size() == 32);
    CHECK(old_uuid.find_first_not_of("0123456789abcdef") == std::string::npos);
    const auto fresh = db.create_trial(1, 1, 2);
    CHECK(db.trial(fresh)->uuid.size() == 32);
    CHECK(db.trial(fresh)->uuid != old_uuid);
    CHECK_FALSE(db.trial(1)->setup_id.has_value());  // version 7: a trial from before has no set-up
    // The analysts' view still reads the renamed table.
    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &raw) == SQLITE_OK);
    sqlite3_stmt* q = nullptr;
    REQUIRE(sqlite3_prepare_v2(raw, "SELECT count(*), sum(value) FROM sample_values WHERE trial_id = 1", -1, &q, nullptr) == SQLITE_OK);
    REQUIRE(sqlite3_step(q) == SQLITE_ROW);
    CHECK(sqlite3_column_int(q, 0) == 4);
    CHECK(sqlite3_column_double(q, 1) == 6.0);
    sqlite3_finalize(q);
    // Version 8 numbered the trial's rows in time order within its id range.
    REQUIRE(sqlite3_prepare_v2(raw, "SELECT id - (1 << 36), mono_ns, channel_id FROM samples ORDER BY id", -1, &q, nullptr) == SQLITE_OK);
    std::vector<std::array<std::int64_t, 3>> ids;
    while (sqlite3_step(q) == SQLITE_ROW)
        ids.push_back({sqlite3_column_int64(q, 0), sqlite3_column_int64(q, 1), sqlite3_column_int64(q, 2)});
    sqlite3_finalize(q);
    CHECK(ids == std::vector<std::array<std::int64_t, 3>>{{0, 10, 1}, {1, 10, 2}, {2, 20, 1}, {3, 20, 2}});
    sqlite3_close(raw);
    // A second write and a duplicate behave as before.
    const SampleRow more[] = {{1, 1, 30, 130, 4.0, 0}, {1, 1, 10, 110, 99.0, 0}};
    CHECK(db.insert_samples(more) == 1);
    CHECK(db.sample_count(1) == 5);
}

TEST_CASE("database: each trial's samples are one id range, numbered as stored, and a query by trial reads only it (v8)", "[recorder]") {
    TempDir dir("ranges");
    const auto path = dir.path / "trials.db";
    auto db = Database::open(path);
    const auto f = make_fixture(db);
    const auto other = db.create_trial(f.campaign, f.case_id, 2);
    // Two trials written turn about, a re-sent reading and an out-of-order one among them.
    for (std::int64_t k = 0; k < 3; ++k) {
        const SampleRow rows[] = {{f.trial, f.channel_a, 100 + k, 0, 1.0, 0}, {other, f.channel_a, 100 + k, 0, 2.0, 0}};
        CHECK(db.insert_samples(rows) == 0);
    }
    const SampleRow late[] = {{f.trial, f.channel_a, 50, 0, 3.0, 0},    // earlier than the newest: new
                              {f.trial, f.channel_a, 101, 0, 9.0, 0},   // re-sent: kept once
                              {other, f.channel_b, 100, 0, 4.0, 0}};    // a channel's first reading
    CHECK(db.insert_samples(late) == 1);
    CHECK(db.sample_count(f.trial) == 4);
    CHECK(db.sample_count(other) == 4);
    std::vector<std::int64_t> order;
    db.for_each_trial_sample(f.trial, [&](const SampleRow& r) { order.push_back(r.mono_ns); });
    CHECK(order == std::vector<std::int64_t>{50, 100, 101, 102});
    CHECK(db.samples(f.trial, f.channel_a).at(2).value == 1.0);  // the first reading at 101
    // A batch sent again (the crash ring's case): what is stored comes out in one scan a trial.
    std::vector<SampleRow> again = {{f.trial, f.channel_a, 102, 0, 1.0, 0}, {f.trial, f.channel_a, 103, 0, 1.0, 0},
                                    {other, f.channel_b, 100, 0, 4.0, 0}, {0, f.channel_a, 5, 5, 1.0, 0}};
    CHECK(db.remove_already_stored(again) == 2);
    REQUIRE(again.size() == 2);
    CHECK(again[0].mono_ns == 103);
    CHECK(again[1].trial_id == 0);  // the idle log's key does its own
    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &raw) == SQLITE_OK);
    const auto first_and_last = [&](std::int64_t trial) {
        sqlite3_stmt* q = nullptr;
        sqlite3_prepare_v2(raw, "SELECT min(id), max(id) FROM samples WHERE trial_id = ?", -1, &q, nullptr);
        sqlite3_bind_int64(q, 1, trial);
        sqlite3_step(q);
        std::pair<std::int64_t, std::int64_t> out{sqlite3_column_int64(q, 0), sqlite3_column_int64(q, 1)};
        sqlite3_finalize(q);
        return out;
    };
    CHECK(first_and_last(f.trial) == std::pair{trial_id_begin(f.trial), trial_id_begin(f.trial) + 3});
    CHECK(first_and_last(other) == std::pair{trial_id_begin(other), trial_id_begin(other) + 3});
    // The analysts' view reads one trial by its range, not the whole table.
    sqlite3_stmt* plan = nullptr;
    REQUIRE(sqlite3_prepare_v2(raw, "EXPLAIN QUERY PLAN SELECT count(*) FROM sample_values WHERE trial_id = 1", -1, &plan,
                               nullptr) == SQLITE_OK);
    std::string details;
    while (sqlite3_step(plan) == SQLITE_ROW) details += std::string(reinterpret_cast<const char*>(sqlite3_column_text(plan, 3))) + "\n";
    sqlite3_finalize(plan);
    sqlite3_close(raw);
    INFO(details);
    CHECK(details.find("SEARCH s USING INTEGER PRIMARY KEY (rowid>? AND rowid<?)") != std::string::npos);
    CHECK(details.find("SCAN s") == std::string::npos);
}

TEST_CASE("database: a set-up is stored once per content and named by its SHA-256, trials point at theirs (v7)", "[recorder]") {
    TempDir dir("setup");
    auto db = Database::open(dir.path / "trials.db");
    const auto f = make_fixture(db);
    CHECK_FALSE(db.trial(f.trial)->setup_id.has_value());  // none until the daemon says
    const Setup a{"lab 1.12", "Weiss WK3 #58226", "ANDI #12", R"({"instruments":{}})", "[lab]\nname = \"lab 1.12\"\n"};
    const auto id = db.record_setup(a, 100);
    CHECK(db.record_setup(a, 200) == id);  // the same content again: the same row, first use kept
    Setup b = a;
    b.calibration_json = R"({"instruments":{"air_temp_c":{"accuracy":0.2}}})";  // a recalibrated probe
    const auto id_b = db.record_setup(b, 300);
    CHECK(id_b != id);
    CHECK(a.sha256() != b.sha256());
    db.set_trial_setup(f.trial, id_b);
    CHECK(db.trial(f.trial)->setup_id == id_b);
    const auto row = db.setup(id);
    REQUIRE(row);
    CHECK(row->sha256 == a.sha256());
    CHECK(row->sha256.size() == 64);
    CHECK(row->first_used_utc_ns == 100);
    CHECK(row->setup.chamber == "Weiss WK3 #58226");
    CHECK(row->setup.manikin == "ANDI #12");
    CHECK(row->setup.config_toml == a.config_toml);
    CHECK(row->setup.calibration_json == a.calibration_json);
    CHECK_FALSE(db.setup(id_b + 1).has_value());
    // Each field counts: a different manikin is a different set-up.
    Setup c = a;
    c.manikin = "ANDI #13";
    CHECK(c.sha256() != a.sha256());
}

TEST_CASE("database: a sample naming a trial or channel that does not exist fails its whole transaction", "[recorder]") {
    TempDir dir("orphan");
    auto db = Database::open(dir.path / "trials.db");
    const auto f = make_fixture(db);
    const SampleRow no_trial[] = {{f.trial, f.channel_a, 1, 10, 1.0, 0}, {f.trial + 7, f.channel_a, 2, 20, 2.0, 0}};
    CHECK_THROWS_WITH(db.insert_samples(no_trial), Catch::Contains("trial " + std::to_string(f.trial + 7) + " does not exist"));
    const SampleRow no_channel[] = {{f.trial, f.channel_a, 1, 10, 1.0, 0}, {f.trial, 999, 2, 20, 2.0, 0}};
    CHECK_THROWS_WITH(db.insert_samples(no_channel), Catch::Contains("channel 999 does not exist"));
    const SampleRow idle_no_channel[] = {{0, 998, 1, 10, 1.0, 0}};
    CHECK_THROWS_WITH(db.insert_samples(idle_no_channel), Catch::Contains("channel 998 does not exist"));
    CHECK(db.sample_count(f.trial) == 0);  // the good first rows went nowhere either
    // SQLite's own checks are back on for everything else.
    CHECK_THROWS_AS(db.create_trial(f.campaign + 50, f.case_id, 1), UserError);
    const SampleRow good[] = {{f.trial, f.channel_b, 1, 10, 1.0, 0}};
    CHECK(db.insert_samples(good) == 0);
    CHECK(db.sample_count(f.trial) == 1);
    CHECK(db.integrity_check() == "ok");
}

TEST_CASE("recorder: 100 000 rows from a producer thread are all committed in order", "[recorder]") {
    TempDir dir("bulk");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path);
    const int rows = 100'000;
    RecorderOptions options;
    options.queue_capacity = 1 << 17;  // room for everything: this test is about order, not drops
    Recorder recorder(path, options);
    std::thread producer([&] {
        for (int i = 0; i < rows; ++i) {
            const auto t = static_cast<std::int64_t>(i / 2);
            recorder.push({f.trial, i % 2 ? f.channel_b : f.channel_a, t * 1000, t * 1000 + 7, static_cast<double>(i),
                           0});
        }
    });
    producer.join();
    recorder.flush();
    const auto stats = recorder.stats();
    CHECK(stats.accepted == rows);
    CHECK(stats.committed == stats.accepted);
    CHECK(stats.dropped == 0);
    CHECK(stats.queue_depth == 0);
    CHECK(stats.batches > 0);

    auto db = Database::open(path);
    CHECK(db.sample_count(f.trial) == rows);
    const auto a = db.samples(f.trial, f.channel_a);
    REQUIRE(a.size() == rows / 2);
    bool ordered = true;
    for (std::size_t i = 0; i < a.size(); ++i)
        ordered = ordered && a[i].mono_ns == static_cast<std::int64_t>(i) * 1000 && a[i].value == static_cast<double>(2 * i);
    CHECK(ordered);
}

TEST_CASE("recorder: a full queue drops and counts rows instead of waiting", "[recorder]") {
    TempDir dir("drop");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path);
    RecorderOptions options;
    options.queue_capacity = 16;
    Recorder recorder(path, options);
    const std::uint64_t pushed = 10'000;
    std::uint64_t refused = 0;
    for (std::uint64_t i = 0; i < pushed; ++i)
        if (!recorder.push({f.trial, f.channel_a, static_cast<std::int64_t>(i), 0, 1.0, 0})) ++refused;
    recorder.flush();
    const auto stats = recorder.stats();
    CHECK(stats.dropped > 0);
    CHECK(stats.dropped == refused);
    CHECK(stats.accepted + stats.dropped == pushed);
    CHECK(stats.committed + stats.dropped == pushed);
    auto db = Database::open(path);
    CHECK(db.sample_count(f.trial) == static_cast<std::int64_t>(stats.committed));
}

TEST_CASE("recorder: offer_many takes the longest prefix that fits, in order, without counting the rest dropped, "
          "and its rows survive kill -9 in the crash ring", "[recorder][crash_ring]") {
    TempDir dir("offer_many");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path);
    std::vector<SampleRow> rows;
    for (std::int64_t i = 0; i < 12; ++i) rows.push_back({f.trial, f.channel_a, i * 1000, i * 1000, static_cast<double>(i), 0});
    {
        RecorderOptions options;
        options.queue_capacity = 8;
        options.max_batch_delay = std::chrono::minutes(10);  // nothing commits unless flushed or the queue fills
        Recorder recorder(path, options);
        CHECK(recorder.offer_many(std::span<const SampleRow>()) == 0);
        const std::size_t first = recorder.offer_many(rows);
        CHECK(first == 8);  // the queue was empty: exactly its capacity, the rest left to the caller
        std::size_t taken = first;
        while (taken < rows.size()) {
            REQUIRE(recorder.flush());
            taken += recorder.offer_many(std::span<const SampleRow>(rows).subspan(taken));
        }
        REQUIRE(recorder.flush());
        const auto stats = recorder.stats();
        CHECK(stats.accepted == 12);
        CHECK(stats.dropped == 0);
        CHECK(stats.committed == 12);
    }
    {
        auto db = Database::open(path);
        const auto a = db.samples(f.trial, f.channel_a);
        REQUIRE(a.size() == 12);
        bool ordered = true;
        for (std::size_t k = 0; k < a.size(); ++k) ordered = ordered && a[k].value == static_cast<double>(k);
        CHECK(ordered);
    }
    RecorderOptions options;
    options.crash_ring_dir = dir.path;
    options.max_batch_delay = std::chrono::minutes(10);
    {
        RecordingChild child([&](const RecordingChild::Report& report) {
            Recorder recorder(path, options);
            std::vector<SampleRow> more;
            for (std::int64_t i = 100; i < 400; ++i) more.push_back({f.trial, f.channel_b, i * 1000, i * 1000, static_cast<double>(i), 0});
            const std::size_t taken = recorder.offer_many(more);
            if (!report(taken)) return;
            for (;;) ::pause();  // killed here, nothing of these committed
        });
        const auto taken = child.next();
        child.kill();
        REQUIRE(taken);
        CHECK(*taken == 300);
    }
    {
        Recorder next(path, options);
        CHECK(next.stats().recovered == 300);
    }
    CHECK(Database::open(path).samples(f.trial, f.channel_b).size() == 300);
}

TEST_CASE("recorder: a re-sent reading is stored once and counted", "[recorder]") {
    TempDir dir("duplicate");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path);
    {
        Recorder recorder(path);
        for (int i = 0; i < 3; ++i) CHECK(recorder.push({f.trial, f.channel_a, 1000, 1000, 1.5, 0}));
        CHECK(recorder.push({f.trial, f.channel_b, 1000, 1000, 2.5, 0}));
        recorder.flush();
        const auto stats = recorder.stats();
        CHECK(stats.accepted == 4);
        CHECK(stats.committed == 2);
        CHECK(stats.duplicates == 2);
        CHECK(stats.queue_depth == 0);
    }
    CHECK(Database::open(path).sample_count(f.trial) == 2);
}

TEST_CASE("recorder: a batch that keeps failing is retried, then counted as lost", "[recorder]") {
    TempDir dir("failing");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path);
    // A poison value makes every attempt at its transaction fail, as a full disk would.
    raw_exec(path, "CREATE TRIGGER poison BEFORE INSERT ON samples WHEN NEW.value = 666"
                   " BEGIN SELECT RAISE(ABORT, 'poisoned sample'); END");
    RecorderOptions options;
    options.max_batch_delay = std::chrono::milliseconds(1);  // also the pause between attempts
    options.max_commit_attempts = 3;
    Recorder recorder(path, options);
    for (int i = 0; i < 10; ++i) recorder.push({f.trial, f.channel_a, i, 0, i == 4 ? 666.0 : 1.0, 0});
    recorder.flush();
    auto stats = recorder.stats();
    CHECK(stats.failed_commits == 3);
    CHECK(stats.lost == 10);  // the whole transaction: SQLite rolls it back
    CHECK(stats.committed == 0);
    CHECK(stats.queue_depth == 0);
    // The writer carries on with the next rows.
    for (int i = 10; i < 20; ++i) recorder.push({f.trial, f.channel_a, i, 0, 1.0, 0});
    recorder.flush();
    stats = recorder.stats();
    CHECK(stats.committed == 10);
    CHECK(stats.accepted == stats.committed + stats.lost);
}

TEST_CASE("recorder: a database locked by another program keeps the rows waiting, never lost, until it lets go",
          "[recorder][journal]") {
    const Journal journal = GENERATE(Journal::wal, Journal::rollback);
    INFO(journal_name(journal));
    TempDir dir("locked");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path, journal);
    RecorderOptions options;
    options.journal = journal;
    options.lock_timeout = std::chrono::milliseconds(20);
    options.max_commit_attempts = 2;  // a failure of another kind would lose the rows after two
    options.crash_ring_dir = dir.path;
    Recorder recorder(path, options);
    // Another program: in WAL mode only a writer blocks the recorder; in rollback mode a reader
    // whose transaction has read something holds its lock until it ends.
    sqlite3* other = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &other) == SQLITE_OK);
    const auto exec = [&](const char* sql) { REQUIRE(sqlite3_exec(other, sql, nullptr, nullptr, nullptr) == SQLITE_OK); };
    if (journal == Journal::wal) {
        exec("BEGIN IMMEDIATE");
    } else {
        exec("BEGIN");
        exec("SELECT count(*) FROM samples");
    }
    for (int i = 1; i <= 100; ++i) recorder.push({f.trial, f.channel_a, i * 1000, i * 1000, static_cast<double>(i), 0});
    for (int attempt = 0; attempt < 4; ++attempt) CHECK_FALSE(recorder.flush());  // twice the attempts allowed
    auto stats = recorder.stats();
    CHECK(stats.locked);
    CHECK(stats.locked_commits >= 4);
    CHECK(stats.lost == 0);
    CHECK(stats.committed == 0);
    CHECK(stats.queue_depth == 100);
    exec("COMMIT");
    sqlite3_close(other);
    CHECK(recorder.flush());
    stats = recorder.stats();
    CHECK_FALSE(stats.locked);
    CHECK(stats.committed == 100);
    CHECK(stats.lost == 0);
    CHECK(Database::open(path).sample_count(f.trial) == 100);
}

TEST_CASE("recorder: kill -9 loses no accepted sample: the next Recorder stores what the crash ring kept", "[recorder][crash_ring]") {
    TempDir dir("ring");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path);  // closed before fork()
    RecorderOptions options;
    options.crash_ring_dir = dir.path;
    options.max_batch_delay = std::chrono::minutes(10);  // nothing commits unless flushed
    {
        RecordingChild child([&](const RecordingChild::Report& report) {
            Recorder recorder(path, options);
            for (std::int64_t i = 1; i <= 1500; ++i) {
                recorder.push({f.trial, i % 2 ? f.channel_a : f.channel_b, i * 1000, i * 1000, static_cast<double>(i), 0});
                if (i == 500) recorder.flush();
            }
            if (!report(recorder.stats().accepted)) return;
            for (;;) ::pause();  // killed here, 1000 samples not committed
        });
        const auto accepted = child.next();
        child.kill();
        REQUIRE(accepted);
        CHECK(*accepted == 1500);
    }
    CHECK(Database::open(path).sample_count(f.trial) == 500);  // what the killed process committed
    {
        Recorder next(path, options);
        CHECK(next.stats().recovered == 1000);
        CHECK_FALSE(next.stats().crash_ring.empty());
    }
    auto db = Database::open(path);
    CHECK(db.sample_count(f.trial) == 1500);
    const auto a = db.samples(f.trial, f.channel_a);
    REQUIRE(a.size() == 750);
    for (std::size_t k = 0; k < a.size(); ++k) CHECK(a[k].value == static_cast<double>(2 * k + 1));
    // A clean stop leaves no ring behind, and a third Recorder has nothing to recover.
    CHECK(std::none_of(fs::directory_iterator(dir.path), fs::directory_iterator(),
                       [](const fs::directory_entry& e) { return e.path().extension() == ".ring"; }));
    Recorder third(path, options);
    CHECK(third.stats().recovered == 0);
}

TEST_CASE("crash ring: readings stored before the crash are not stored twice, nor rows whose trial is gone", "[recorder][crash_ring]") {
    TempDir dir("ring-twice");
    const auto path = dir.path / "trials.db";
    auto db = Database::open(path);
    const auto f = make_fixture(db);
    std::vector<SampleRow> rows;
    for (std::int64_t i = 1; i <= 15; ++i) rows.push_back({f.trial, f.channel_a, i * 10, i * 10, static_cast<double>(i), 0});
    db.insert_samples(std::span<const SampleRow>(rows.data(), 10));
    {
        // A writer that died after committing 1..10 but before trimming its ring from 6 on.
        std::string why_not;
        auto ring = CrashRing::open(dir.path, path, 64, why_not);
        REQUIRE(ring);
        for (std::size_t k = 5; k < 15; ++k) ring->append(rows[k]);
        ring->append({f.trial + 40, f.channel_a, 999, 999, 1.0, 0});  // a trial this file does not have
    }
    RecorderOptions options;
    options.crash_ring_dir = dir.path;
    {
        Recorder next(path, options);
        CHECK(next.stats().recovered == 5);
        // While it holds the ring, a second Recorder on the same file runs without one.
        Recorder second(path, options);
        CHECK(second.stats().crash_ring.empty());
        CHECK_FALSE(next.stats().crash_ring.empty());
    }
    CHECK(db.sample_count(f.trial) == 15);
    const auto back = db.samples(f.trial, f.channel_a);
    REQUIRE(back.size() == 15);
    CHECK(back.back().value == 15.0);
}

TEST_CASE("crash ring: a directory that cannot hold it leaves the Recorder working without one", "[recorder][crash_ring]") {
    TempDir dir("ring-none");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path);
    RecorderOptions options;
    options.crash_ring_dir = dir.path / "no-such-dir";
    Recorder recorder(path, options);
    CHECK(recorder.stats().crash_ring.empty());
    CHECK(recorder.push({f.trial, f.channel_a, 1, 1, 1.0, 0}));
    CHECK(recorder.flush());
    CHECK(recorder.stats().committed == 1);
}

TEST_CASE("recorder: an unopenable path throws from the constructor", "[recorder]") {
    TempDir dir("unopenable");
    CHECK_THROWS_WITH(Recorder(dir.path / "missing" / "trials.db"), Catch::Contains("missing"));
}

TEST_CASE("recorder: a SIGKILL mid-recording keeps every flushed row and a sound file", "[recorder]") {
    const Journal journal = GENERATE(Journal::wal, Journal::rollback);
    INFO(journal_name(journal));
    TempDir dir("crash");
    const auto path = dir.path / "trials.db";
    // Closed before fork(): an SQLite connection must not cross into a child.
    const Fixture f = fixture_file(path, journal, Durability::process, "acquiring");

    RecordingChild child([&](const RecordingChild::Report& report) {
        RecorderOptions options;
        options.crash_ring_dir = dir.path;  // left behind by the kill: not in /dev/shm
        options.journal = journal;
        Recorder recorder(path, options);
        for (std::int64_t i = 1;; ++i) {
            recorder.push({f.trial, f.channel_a, i * 1000, i * 1000, static_cast<double>(i), 0});
            if (i % 1000 == 0) {
                recorder.flush();
                if (!report(recorder.stats().committed)) return;
            }
        }
    });
    const int wanted_reports = 20;
    int reports = 0;
    std::uint64_t last_committed = 0;
    while (reports < wanted_reports) {
        const auto committed = child.next();
        if (!committed) break;
        last_committed = *committed;
        ++reports;
    }
    const int status = child.kill();  // while it is pushing the next thousand rows
    REQUIRE(reports == wanted_reports);
    CHECK(WIFSIGNALED(status));
    CHECK(last_committed == wanted_reports * 1000);

    auto db = Database::open(path);
    CHECK(db.integrity_check() == "ok");
    const auto count = db.sample_count(f.trial);
    CHECK(count >= static_cast<std::int64_t>(last_committed));
    const auto samples = db.samples(f.trial, f.channel_a);
    REQUIRE(!samples.empty());
    CHECK(samples.back().mono_ns == count * 1000);  // a prefix, no holes

    CHECK(db.trial(f.trial)->state == "acquiring");
    CHECK(db.mark_interrupted_trials(123) == 1);
    const auto t = db.trial(f.trial);
    CHECK(t->state == "interrupted");
    CHECK(t->reason == "daemon restarted");
    CHECK(t->ended_utc_ns == 123);
    CHECK(db.mark_interrupted_trials(124) == 0);
}

TEST_CASE("recorder: the files copied at random instants while writing, as a power cut leaves them, open sound and "
          "consistent (durability = power)",
          "[recorder][durability]") {
    const Journal journal = GENERATE(Journal::wal, Journal::rollback);
    INFO(journal_name(journal));
    TempDir dir("powercut");
    const auto path = dir.path / "trials.db";
    const Fixture f = fixture_file(path, journal, Durability::power);  // closed before fork()

    RecordingChild child([&](const RecordingChild::Report& report) {
        // The daemon's two connections: the Recorder's for samples, one for trial states and events.
        auto db = Database::open(path, manikind::recorder::Durability::power, journal);
        manikind::recorder::RecorderOptions options;
        options.durability = manikind::recorder::Durability::power;
        options.journal = journal;
        options.crash_ring_dir = dir.path;
        Recorder recorder(path, options);
        for (std::int64_t i = 1;; ++i) {
            recorder.push({f.trial, f.channel_a, i * 1000, i * 1000, static_cast<double>(i), 0});
            if (i % 500 == 0) {
                recorder.flush();
                db.set_trial_state(f.trial, (i / 500) % 2 ? "acquiring" : "chamber_settling", "", i);
                db.add_event(f.trial, i * 1000, i * 1000, "info", "stage", std::to_string(i));
                if (!report(recorder.stats().committed)) return;
            }
        }
    });
    // At 12 of the first 60 reports (which ones: a fixed pseudo-random draw), freeze the writer
    // wherever it is (mid-commit or not), copy the database and its WAL or rollback journal but
    // not the -shm index (rebuilt after a reboot), and let it go on.
    std::mt19937 draw(20261124);
    std::vector<int> stop_at;
    for (int k = 0; k < 12; ++k) stop_at.push_back(5 * k + static_cast<int>(draw() % 5));
    std::vector<std::pair<fs::path, std::uint64_t>> copies;  // copy folder, rows committed before it
    for (int report = 0; report < 60; ++report) {
        const auto reported = child.next();
        if (!reported) break;
        const std::uint64_t committed = *reported;
        if (std::find(stop_at.begin(), stop_at.end(), report) == stop_at.end()) continue;
        // Let the writer run into its next batch, then freeze it at that instant.
        for (int spin = 0; spin < 1000 + report * 997 % 20000; ++spin) std::atomic_signal_fence(std::memory_order_seq_cst);
        ::kill(child.pid(), SIGSTOP);
        int stopped = 0;
        ::waitpid(child.pid(), &stopped, WUNTRACED);
        const fs::path copy = dir.path / ("copy-" + std::to_string(report));
        fs::create_directories(copy);
        fs::copy_file(path, copy / "trials.db");
        for (const char* suffix : {"-wal", "-journal"})
            if (fs::exists(path.string() + suffix)) fs::copy_file(path.string() + suffix, copy / ("trials.db" + std::string(suffix)));
        copies.emplace_back(copy, committed);
        ::kill(child.pid(), SIGCONT);
    }
    child.kill();
    REQUIRE(copies.size() == stop_at.size());

    for (const auto& [copy, committed_before] : copies) {
        INFO(copy.string());
        auto db = Database::open(copy / "trials.db");
        CHECK(db.integrity_check() == "ok");
        // Every row committed before the freeze is there, as a prefix without holes.
        const auto samples = db.samples(f.trial, f.channel_a);
        REQUIRE(samples.size() >= committed_before);
        CHECK(samples.back().mono_ns == static_cast<std::int64_t>(samples.size()) * 1000);
        // The trial row and the events, written through the other connection, agree with each other.
        const auto trial = db.trial(f.trial);
        REQUIRE(trial);
        CHECK((trial->state == "acquiring" || trial->state == "chamber_settling" || trial->state == "pending"));
        const auto events = db.events(f.trial);
        if (!events.empty()) {
            // The state of the last event's step, or of the next one when the freeze fell between
            // that step's state update and its event (two transactions).
            const long last_event_row = std::stol(events.back().message);
            const auto state_at = [](long row) { return (row / 500) % 2 ? "acquiring" : "chamber_settling"; };
            CHECK((trial->state == state_at(last_event_row) || trial->state == state_at(last_event_row + 500)));
        }
    }
}
