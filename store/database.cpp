#include "store/database.hpp"

#include <sqlite3.h>

#include <cerrno>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "base/sha256.hpp"
#include "base/user_error.hpp"

namespace manikind::recorder {
namespace {

// Version 1: the full schema. samples is the hot table: WITHOUT ROWID keyed by (trial, channel,
// time) is one b-tree instead of a rowid table plus an index, which measured 14 % faster to
// fill and 34 % smaller than the pair (docs/recorder.md), and serves the time-ordered reads.
constexpr const char* migration_1 = R"sql(
CREATE TABLE campaigns (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    definition_json TEXT NOT NULL,
    created_utc_ns INTEGER NOT NULL,
    state TEXT NOT NULL DEFAULT 'created'
);
CREATE TABLE cases (
    id INTEGER PRIMARY KEY,
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    name TEXT NOT NULL,
    conditions_json TEXT NOT NULL,
    position INTEGER NOT NULL,
    UNIQUE (campaign_id, name)
);
CREATE TABLE trials (
    id INTEGER PRIMARY KEY,
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    case_id INTEGER NOT NULL REFERENCES cases(id),
    replicate INTEGER NOT NULL,
    state TEXT NOT NULL DEFAULT 'pending',
    reason TEXT NOT NULL DEFAULT '',
    started_utc_ns INTEGER,
    ended_utc_ns INTEGER,
    steady_from_mono_ns INTEGER,
    quality_flags INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE devices (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    kind TEXT NOT NULL,
    address TEXT NOT NULL
);
CREATE TABLE channels (
    id INTEGER PRIMARY KEY,
    device_id INTEGER NOT NULL REFERENCES devices(id),
    name TEXT NOT NULL,
    unit TEXT NOT NULL,
    UNIQUE (device_id, name)
);
CREATE TABLE samples (
    trial_id INTEGER NOT NULL REFERENCES trials(id),
    channel_id INTEGER NOT NULL REFERENCES channels(id),
    mono_ns INTEGER NOT NULL,
    utc_ns INTEGER NOT NULL,
    value REAL,
    quality INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (trial_id, channel_id, mono_ns)
) WITHOUT ROWID;
CREATE TABLE events (
    id INTEGER PRIMARY KEY,
    trial_id INTEGER REFERENCES trials(id),
    mono_ns INTEGER NOT NULL,
    utc_ns INTEGER NOT NULL,
    severity TEXT NOT NULL,
    kind TEXT NOT NULL,
    message TEXT NOT NULL
);
CREATE TABLE results (
    id INTEGER PRIMARY KEY,
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    computed_utc_ns INTEGER NOT NULL,
    json TEXT NOT NULL
);
CREATE TABLE twin_versions (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL,
    version INTEGER NOT NULL,
    toml TEXT NOT NULL,
    created_utc_ns INTEGER NOT NULL,
    UNIQUE (name, version)
);
)sql";

// Version 2: indexes for the per-campaign and per-trial lookups (trials(campaign_id),
// events(trial_id), latest_result), which version 1 answered by full scans.
constexpr const char* migration_2 = R"sql(
CREATE INDEX trials_by_campaign ON trials (campaign_id);
CREATE INDEX events_by_trial_time ON events (trial_id, mono_ns);
CREATE INDEX results_by_campaign_time ON results (campaign_id, computed_utc_ns);
)sql";

// Version 3: the idle log. Readings outside any trial (before, between and after campaigns) at
// [lab] idle_log_period_s, so the chamber's history before a trial is kept. Keyed by wall time:
// the monotonic clock restarts with the daemon.
constexpr const char* migration_3 = R"sql(
CREATE TABLE idle_samples (
    channel_id INTEGER NOT NULL REFERENCES channels(id),
    utc_ns INTEGER NOT NULL,
    mono_ns INTEGER NOT NULL,
    value REAL,
    quality INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (channel_id, utc_ns)
) WITHOUT ROWID;
)sql";

// Version 4: views for analysts (docs/recorder.md, "Reading the database"). A trial's time base
// is the manikin's start (the "acquiring" stage), as in the exports; results come from the
// latest stored analysis of each campaign. trial_table, with a column per channel, depends on
// the channels and is kept current by refresh_trial_table().
constexpr const char* migration_4 = R"sql(
CREATE VIEW trial_info AS
SELECT t.id AS trial_id, c.name AS campaign, k.name AS case_name,
       COALESCE(json_extract(k.conditions_json, '$.id'), k.position + 1) AS case_number,
       t.replicate AS replicate, t.state AS state, t.reason AS reason,
       (SELECT e.mono_ns FROM events e WHERE e.trial_id = t.id AND e.kind = 'stage' AND e.message = 'acquiring'
        ORDER BY e.mono_ns LIMIT 1) AS t0_mono_ns,
       (SELECT e.utc_ns FROM events e WHERE e.trial_id = t.id AND e.kind = 'stage' AND e.message = 'acquiring'
        ORDER BY e.mono_ns LIMIT 1) AS t0_utc_ns,
       t.started_utc_ns AS started_utc_ns, t.ended_utc_ns AS ended_utc_ns
FROM trials t JOIN campaigns c ON c.id = t.campaign_id JOIN cases k ON k.id = t.case_id;

CREATE VIEW sample_values AS
WITH t0 AS MATERIALIZED (SELECT trial_id, min(mono_ns) AS t0_mono_ns FROM events
                         WHERE kind = 'stage' AND message = 'acquiring' GROUP BY trial_id)
SELECT s.trial_id AS trial_id, c.name AS campaign, COALESCE(json_extract(k.conditions_json, '$.id'), k.position + 1) AS case_number,
       t.replicate AS replicate, d.name AS device, ch.name AS channel, d.name || '.' || ch.name AS column_name, ch.unit AS unit,
       (s.mono_ns - t0.t0_mono_ns) / 1e9 AS t_s, s.utc_ns AS utc_ns, s.value AS value, s.quality AS quality
FROM samples s JOIN trials t ON t.id = s.trial_id JOIN campaigns c ON c.id = t.campaign_id JOIN cases k ON k.id = t.case_id
     LEFT JOIN t0 ON t0.trial_id = s.trial_id
     JOIN channels ch ON ch.id = s.channel_id JOIN devices d ON d.id = ch.device_id;

CREATE VIEW latest_results AS
SELECT r.* FROM results r
WHERE r.id = (SELECT r2.id FROM results r2 WHERE r2.campaign_id = r.campaign_id
              ORDER BY r2.computed_utc_ns DESC, r2.id DESC LIMIT 1);

CREATE VIEW case_results AS
SELECT c.name AS campaign, json_extract(k.value, '$.case') AS case_number,
       json_extract(k.value, '$.n_replicates') AS n_replicates,
       json_extract(k.value, '$.whole_body.q_w_m2') AS q_wb_w_m2,
       json_extract(k.value, '$.whole_body.U') AS u95_w_m2,
       json_extract(k.value, '$.whole_body.k') AS k,
       json_extract(k.value, '$.whole_body.u_a') AS u_a_w_m2,
       json_extract(k.value, '$.whole_body.u_b') AS u_b_w_m2,
       r.computed_utc_ns AS computed_utc_ns
FROM latest_results r JOIN campaigns c ON c.id = r.campaign_id, json_each(r.json, '$.cases') k;

CREATE VIEW trial_results AS
SELECT c.name AS campaign, json_extract(k.value, '$.case') AS case_number,
       json_extract(t.value, '$.id') AS trial, json_extract(t.value, '$.replicate') AS replicate,
       json_extract(t.value, '$.included') AS included, json_extract(t.value, '$.steady') AS steady,
       json_extract(t.value, '$.window_start_s') AS window_start_s, json_extract(t.value, '$.window_end_s') AS window_end_s,
       json_extract(t.value, '$.whole_body_q_w_m2') AS q_wb_w_m2, json_extract(t.value, '$.reason') AS reason
FROM latest_results r JOIN campaigns c ON c.id = r.campaign_id, json_each(r.json, '$.cases') k,
     json_each(k.value, '$.trials') t;
)sql";

// Version 5: samples keyed time-major, (trial, time, channel). Rows arrive in time order, so
// each commit appends to the right edge of one b-tree instead of touching a leaf per channel:
// at the lab's rate with 1-s commits that writes 12x the data instead of 164x (docs/recorder.md,
// "Write amplification"). Reads by trial stay a key-prefix range; reads of one channel scan its
// trial. The idle log likewise becomes (time, channel): 157 channels every 10 s touched 157
// leaves per commit when keyed by channel first. The views name `samples` and stay valid: legacy_alter_table lets the rename through
// without re-checking them (the old table is gone by then) and is set back after.
constexpr const char* migration_5 = R"sql(
CREATE TABLE samples_v5 (
    trial_id INTEGER NOT NULL REFERENCES trials(id),
    mono_ns INTEGER NOT NULL,
    channel_id INTEGER NOT NULL REFERENCES channels(id),
    utc_ns INTEGER NOT NULL,
    value REAL,
    quality INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (trial_id, mono_ns, channel_id)
) WITHOUT ROWID;
INSERT INTO samples_v5 (trial_id, mono_ns, channel_id, utc_ns, value, quality)
SELECT trial_id, mono_ns, channel_id, utc_ns, value, quality FROM samples ORDER BY trial_id, mono_ns, channel_id;
DROP TABLE samples;
CREATE TABLE idle_samples_v5 (
    utc_ns INTEGER NOT NULL,
    channel_id INTEGER NOT NULL REFERENCES channels(id),
    mono_ns INTEGER NOT NULL,
    value REAL,
    quality INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (utc_ns, channel_id)
) WITHOUT ROWID;
INSERT INTO idle_samples_v5 (utc_ns, channel_id, mono_ns, value, quality)
SELECT utc_ns, channel_id, mono_ns, value, quality FROM idle_samples ORDER BY utc_ns, channel_id;
DROP TABLE idle_samples;
PRAGMA legacy_alter_table = ON;
ALTER TABLE samples_v5 RENAME TO samples;
ALTER TABLE idle_samples_v5 RENAME TO idle_samples;
PRAGMA legacy_alter_table = OFF;
)sql";

// Version 6: a trial's UUID, so a trial keeps one name beyond this file (an archive that many
// daemons write into keys rows by it; docs/recorder.md). Trials from before get one now.
constexpr const char* migration_6 = R"sql(
ALTER TABLE trials ADD COLUMN uuid TEXT;
UPDATE trials SET uuid = lower(hex(randomblob(16))) WHERE uuid IS NULL;
CREATE UNIQUE INDEX trials_by_uuid ON trials (uuid);
)sql";

// Version 7: the set-up each trial ran with (docs/recorder.md, "Set-ups"): which lab, chamber and
// manikin, the instruments' Type B specifications and register maps (probe scaling), and the
// configuration text, stored once per distinct content and named by its SHA-256.
constexpr const char* migration_7 = R"sql(
CREATE TABLE setups (
    id INTEGER PRIMARY KEY,
    sha256 TEXT NOT NULL UNIQUE,
    lab_name TEXT NOT NULL,
    chamber TEXT NOT NULL,
    manikin TEXT NOT NULL,
    calibration_json TEXT NOT NULL,
    config_toml TEXT NOT NULL,
    first_used_utc_ns INTEGER NOT NULL
);
ALTER TABLE trials ADD COLUMN setup_id INTEGER REFERENCES setups(id);
)sql";

// Version 8: samples in a rowid table, each trial one rowid range: id = (trial_id << 36) + n, n
// counting the trial's rows in the order they were stored. A trial's rows are appended at the
// right edge of one b-tree with SQLite's quick balance and an integer key, which the composite
// WITHOUT ROWID key of version 5 could not do (raw C: 1.8 against 1.4 M rows/s, the plain
// append-only table 2.1; docs/recorder.md, "Why samples is a rowid range per trial"). Reads by
// trial are a rowid range; insert_samples keeps "a re-sent reading is stored once" itself.
// The views join trials to samples by that range, so a filter on their trial_id stays a range.
constexpr const char* migration_8 = R"sql(
CREATE TABLE samples_v8 (
    id INTEGER PRIMARY KEY,
    trial_id INTEGER NOT NULL REFERENCES trials(id),
    mono_ns INTEGER NOT NULL,
    channel_id INTEGER NOT NULL REFERENCES channels(id),
    utc_ns INTEGER NOT NULL,
    value REAL,
    quality INTEGER NOT NULL DEFAULT 0
);
INSERT INTO samples_v8 (id, trial_id, mono_ns, channel_id, utc_ns, value, quality)
SELECT (trial_id << 36) + row_number() OVER (PARTITION BY trial_id ORDER BY mono_ns, channel_id) - 1,
       trial_id, mono_ns, channel_id, utc_ns, value, quality
FROM samples ORDER BY trial_id, mono_ns, channel_id;
DROP VIEW IF EXISTS trial_table;
DROP VIEW sample_values;
DROP TABLE samples;
PRAGMA legacy_alter_table = ON;
ALTER TABLE samples_v8 RENAME TO samples;
PRAGMA legacy_alter_table = OFF;
CREATE VIEW sample_values AS
WITH t0 AS MATERIALIZED (SELECT trial_id, min(mono_ns) AS t0_mono_ns FROM events
                         WHERE kind = 'stage' AND message = 'acquiring' GROUP BY trial_id)
SELECT t.id AS trial_id, c.name AS campaign, COALESCE(json_extract(k.conditions_json, '$.id'), k.position + 1) AS case_number,
       t.replicate AS replicate, d.name AS device, ch.name AS channel, d.name || '.' || ch.name AS column_name, ch.unit AS unit,
       (s.mono_ns - t0.t0_mono_ns) / 1e9 AS t_s, s.utc_ns AS utc_ns, s.value AS value, s.quality AS quality
FROM trials t JOIN samples s ON s.id >= (t.id << 36) AND s.id < ((t.id + 1) << 36)
     JOIN campaigns c ON c.id = t.campaign_id JOIN cases k ON k.id = t.case_id
     LEFT JOIN t0 ON t0.trial_id = t.id
     JOIN channels ch ON ch.id = s.channel_id JOIN devices d ON d.id = ch.device_id;
)sql";

// Version 9: the lab notebook (issue 35; docs/recorder.md, "Notes"): notes per campaign and,
// optionally, per trial, each with its author, kind and time. Append-only: the triggers refuse an
// edit or a deletion, so what was written on the day stays as written (a correction is a new note).
constexpr const char* migration_9 = R"sql(
CREATE TABLE notes (
    id INTEGER PRIMARY KEY,
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    trial_id INTEGER REFERENCES trials(id),
    utc_ns INTEGER NOT NULL,
    author TEXT NOT NULL,
    kind TEXT NOT NULL CHECK (kind IN ('comment', 'operator', 'ensemble', 'garment')),
    text TEXT NOT NULL
);
CREATE INDEX notes_by_campaign ON notes (campaign_id, utc_ns);
CREATE TRIGGER notes_no_update BEFORE UPDATE ON notes BEGIN SELECT RAISE(ABORT, 'notes are append-only'); END;
CREATE TRIGGER notes_no_delete BEFORE DELETE ON notes BEGIN SELECT RAISE(ABORT, 'notes are append-only'); END;
)sql";

// Append only: a released migration is never edited, a change is a new entry.
constexpr std::array<const char*, 9> all_migrations{migration_1, migration_2, migration_3, migration_4, migration_5,
                                                    migration_6, migration_7, migration_8, migration_9};

// SQL text of trial_table for the channels stored now: one row per trial and 5-s step of the
// exports' grid ((t - 5 s, t] after the manikin's start), a column "<device>.<channel>" per
// channel with the mean of its good samples and "<device>.<channel>.q" with the best (lowest)
// quality code in the step. Aggregates with FILTER: 2.4x faster than CASE inside avg() on a
// 157-channel trial, and the start time is a materialized CTE, not a subquery per sample.
std::string trial_table_sql(sqlite3* db) {
    std::string columns;
    sqlite3_stmt* q = nullptr;
    sqlite3_prepare_v2(db,
                       "SELECT ch.id, d.name || '.' || ch.name FROM channels ch JOIN devices d ON d.id = ch.device_id "
                       "ORDER BY d.name, ch.name",
                       -1, &q, nullptr);
    while (q && sqlite3_step(q) == SQLITE_ROW) {
        const auto id = sqlite3_column_int64(q, 0);
        std::string name = reinterpret_cast<const char*>(sqlite3_column_text(q, 1));
        std::string quoted;  // an SQL identifier: double quotes doubled
        for (const char ch : name) quoted += ch == '"' ? std::string("\"\"") : std::string(1, ch);
        columns += fmt::format(",\n  avg(s.value) FILTER (WHERE s.channel_id = {0} AND s.quality = 0) AS \"{1}\""
                               ",\n  min(s.quality) FILTER (WHERE s.channel_id = {0}) AS \"{1}.q\"",
                               id, quoted);
    }
    sqlite3_finalize(q);
    return "CREATE VIEW trial_table AS\n"
           "WITH t0 AS MATERIALIZED (SELECT trial_id, min(mono_ns) AS t0_mono_ns, utc_ns AS t0_utc_ns FROM events\n"
           "                         WHERE kind = 'stage' AND message = 'acquiring' GROUP BY trial_id)\n"
           "SELECT s.trial_id AS trial_id, s.step * 5.0 AS t_s, s.t0_utc_ns + s.step * 5000000000 AS utc_ns" +
           columns +
           "\nFROM (SELECT t0.trial_id, x.channel_id, x.value, x.quality, t0.t0_utc_ns,"
           " CASE WHEN x.mono_ns > t0.t0_mono_ns THEN (x.mono_ns - t0.t0_mono_ns + 4999999999) / 5000000000"
           " ELSE (x.mono_ns - t0.t0_mono_ns) / 5000000000 END AS step"
           " FROM t0 JOIN samples x ON x.id >= (t0.trial_id << 36) AND x.id < ((t0.trial_id + 1) << 36)) s\n"
           "GROUP BY s.trial_id, s.step";
}

std::int64_t utc_now_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

std::string column_text(sqlite3_stmt* s, int i) {
    const auto* p = sqlite3_column_text(s, i);
    return p ? std::string(reinterpret_cast<const char*>(p), static_cast<std::size_t>(sqlite3_column_bytes(s, i)))
             : std::string();
}

std::optional<std::int64_t> column_optional_int(sqlite3_stmt* s, int i) {
    if (sqlite3_column_type(s, i) == SQLITE_NULL) return std::nullopt;
    return sqlite3_column_int64(s, i);
}

}  // namespace

bool is_terminal_trial_state(std::string_view state) {
    return state == "done" || state == "aborted" || state == "interrupted" || state == "failed";
}

struct Database::Impl {
    sqlite3* db = nullptr;
    std::filesystem::path path;
    // Prepared once per connection. Keyed by the SQL text without a copy, so callers pass
    // string literals or static strings only.
    std::unordered_map<std::string_view, sqlite3_stmt*> statements;
    sqlite3_stmt* insert_sample = nullptr;  // the hot one, kept out of the map lookup
    sqlite3_stmt* insert_idle_sample = nullptr;  // rows with trial_id 0: the idle log
    // Trials and channels known to exist. Nothing deletes either, so an id seen once stays valid;
    // insert_samples checks ids here instead of by SQLite's foreign-key lookups (docs/recorder.md).
    std::unordered_set<std::int64_t> known_trials, known_channels;
    // Where each trial's rows end, as this connection last saw them: the next id to give and
    // each channel's newest mono_ns stored, so a re-sent reading is found without a key
    // (version 8). Checked against the stored maximum id at every transaction: another
    // connection that wrote the trial, or a rolled-back transaction, makes it reload.
    struct TrialTail {
        std::int64_t next_id = 0;
        std::unordered_map<std::int64_t, std::int64_t> newest_mono_ns;  // by channel id
    };
    std::unordered_map<std::int64_t, TrialTail> trial_tails;

    ~Impl() {
        for (auto& [sql, s] : statements) sqlite3_finalize(s);
        sqlite3_close_v2(db);  // a WAL database is checkpointed when its last connection closes
    }

    [[noreturn]] void fail(std::string_view what) const {
        if (!db) throw UserError(fmt::format("{}: {}: out of memory", path.string(), what));
        fail_with(sqlite3_errcode(db), sqlite3_system_errno(db), what, sqlite3_errmsg(db));
    }
    // The exception for an SQLite error: the storage kinds the recorder waits out, else UserError.
    [[noreturn]] void fail_with(int code, int sys_errno, std::string_view what, const std::string& message) const {
        const std::string text = fmt::format("{}: {}: {}", path.string(), what, message);
        if ((code & 0xff) == SQLITE_FULL || sys_errno == ENOSPC) throw StorageFull(text);
        if ((code & 0xff) == SQLITE_BUSY || (code & 0xff) == SQLITE_LOCKED) throw StorageBusy(text);
        if ((code & 0xff) == SQLITE_IOERR) throw StorageFault(text);
        throw UserError(text);
    }

    void exec(const char* sql, std::string_view what) {
        if (sqlite3_exec(db, sql, nullptr, nullptr, nullptr) != SQLITE_OK) fail(what);
    }

    sqlite3_stmt* statement(std::string_view sql) {
        if (auto it = statements.find(sql); it != statements.end()) return it->second;
        sqlite3_stmt* s = nullptr;
        if (sqlite3_prepare_v3(db, sql.data(), static_cast<int>(sql.size()), SQLITE_PREPARE_PERSISTENT, &s, nullptr) !=
            SQLITE_OK)
            fail(fmt::format("preparing '{}'", sql));
        statements.emplace(sql, s);
        return s;
    }
};

namespace {

// One use of a cached statement: binds left to right, steps, and resets on scope exit so the
// statement is ready for the next caller even after an exception.
class Query {
public:
    Query(Database::Impl& impl, std::string_view sql) : impl_(impl), s_(impl.statement(sql)) {}
    Query(const Query&) = delete;
    Query& operator=(const Query&) = delete;
    ~Query() {
        sqlite3_reset(s_);
        sqlite3_clear_bindings(s_);
    }

    template <typename... Args>
    Query& bind(const Args&... args) {
        (bind_one(args), ...);
        return *this;
    }

    // True while there is a row to read; false when done. Throws on error.
    bool step() {
        const int rc = sqlite3_step(s_);
        if (rc == SQLITE_ROW) return true;
        if (rc == SQLITE_DONE) return false;
        impl_.fail(fmt::format("running '{}'", sqlite3_sql(s_)));
    }

    // Steps once, expecting no row (INSERT, UPDATE).
    void run() {
        while (step()) {
        }
    }

    std::int64_t integer(int i) const { return sqlite3_column_int64(s_, i); }
    double real(int i) const {
        return sqlite3_column_type(s_, i) == SQLITE_NULL ? std::numeric_limits<double>::quiet_NaN()
                                                          : sqlite3_column_double(s_, i);
    }
    std::string text(int i) const { return column_text(s_, i); }
    std::optional<std::int64_t> optional_integer(int i) const { return column_optional_int(s_, i); }
    // SQLite's (extended) result code, for callers that turn some failures into better messages.
    int step_code() { return sqlite3_step(s_); }

private:
    void check(int rc) {
        if (rc != SQLITE_OK) impl_.fail("binding a parameter");
    }
    void bind_one(std::int64_t v) { check(sqlite3_bind_int64(s_, ++index_, v)); }
    void bind_one(int v) { check(sqlite3_bind_int64(s_, ++index_, v)); }
    void bind_one(double v) {
        // SQLite has no NaN: it stores NULL, and real() reads NULL back as NaN.
        check(std::isnan(v) ? sqlite3_bind_null(s_, ++index_) : sqlite3_bind_double(s_, ++index_, v));
    }
    void bind_one(const std::string& v) {
        // The bound text must outlive step(); every caller binds named arguments, not temporaries.
        check(sqlite3_bind_text(s_, ++index_, v.data(), static_cast<int>(v.size()), nullptr));
    }
    void bind_one(const char* v) { check(sqlite3_bind_text(s_, ++index_, v, -1, nullptr)); }
    void bind_one(const std::optional<std::int64_t>& v) {
        check(v ? sqlite3_bind_int64(s_, ++index_, *v) : sqlite3_bind_null(s_, ++index_));
    }

    Database::Impl& impl_;
    sqlite3_stmt* s_;
    int index_ = 0;
};

// BEGIN IMMEDIATE takes the write lock up front, so the transaction cannot fail half way
// for want of it (a deferred one could get SQLITE_BUSY at its first write).
class Transaction {
public:
    explicit Transaction(Database::Impl& impl) : impl_(impl) {
        Query(impl_, "BEGIN IMMEDIATE").run();
    }
    Transaction(const Transaction&) = delete;
    Transaction& operator=(const Transaction&) = delete;
    ~Transaction() {
        if (!done_) sqlite3_exec(impl_.db, "ROLLBACK", nullptr, nullptr, nullptr);
    }
    void commit() {
        Query(impl_, "COMMIT").run();
        done_ = true;
    }

private:
    Database::Impl& impl_;
    bool done_ = false;
};

int user_version(Database::Impl& impl) {
    Query q(impl, "PRAGMA user_version");
    q.step();
    return static_cast<int>(q.integer(0));
}

std::string journal_mode_of(Database::Impl& impl) {
    Query q(impl, "PRAGMA journal_mode");
    q.step();
    return q.text(0);
}

void migrate(Database::Impl& impl) {
    const int latest = static_cast<int>(all_migrations.size());
    // One transaction per step, re-reading the version inside it, so two processes opening a
    // new file at once cannot both apply a step, and a crash leaves the last completed version.
    std::optional<bool> existing;  // whether the file held a schema when opened: only then is a step worth a warning
    for (;;) {
        Transaction tx(impl);
        const int version = user_version(impl);
        if (!existing) existing = version > 0;
        if (version > latest)
            throw UserError(fmt::format("{}: database schema version {} is newer than this program knows (latest {}); "
                                        "use a newer manikind or another file",
                                        impl.path.string(), version, latest));
        if (version == latest) {
            tx.commit();
            return;
        }
        // A step that copies the samples (versions 5 and 8) takes about a second per million
        // rows: say so, or a daemon upgrading weeks of recordings looks hung at start.
        if (*existing)
            spdlog::warn("{}: upgrading the database schema from version {} to {} (a large file takes a while)",
                         impl.path.string(), version, version + 1);
        impl.exec(all_migrations[static_cast<std::size_t>(version)],
                  fmt::format("migrating the schema from version {} to {}", version, version + 1));
        impl.exec(fmt::format("PRAGMA user_version = {}", version + 1).c_str(), "setting the schema version");
        tx.commit();
    }
}

}  // namespace

Database::Database(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Database::Database(Database&&) noexcept = default;
Database& Database::operator=(Database&&) noexcept = default;
Database::~Database() = default;

std::span<const char* const> Database::migrations() { return all_migrations; }
int Database::latest_schema_version() { return static_cast<int>(all_migrations.size()); }

namespace {
// SQLite counts every allocation for sqlite3_memory_used() under a process-wide mutex unless told
// not to (SQLITE_CONFIG_MEMSTATUS, on by default). Nothing here reads those counts, and the
// recorder allocates per statement step: the lock and unlock were 6 % of the demo's CPU (perf).
// sqlite3_config must come before SQLite initialises, so it is set before main, in every program
// that links the store: a program that touches SQLite raw before its first Database::open (the
// archive's pull reads a source file so) would otherwise initialise it with the counters on.
const bool sqlite_counters_off = sqlite3_config(SQLITE_CONFIG_MEMSTATUS, 0) == SQLITE_OK;
}  // namespace

Database Database::open(const std::filesystem::path& path, Durability durability, std::optional<Journal> journal) {
    auto impl = std::make_unique<Impl>();
    impl->path = path;
    // Created 0640 (or tighter, by the umask): recordings are the lab's, not every local user's. SQLite
    // gives the -wal and -shm files the database file's mode.
    bool new_file = false;
    if (const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0640); fd >= 0) {
        ::close(fd);
        new_file = true;
    } else {
        std::error_code ec;
        new_file = std::filesystem::file_size(path, ec) == 0 && !ec;
    }
    if (sqlite3_open_v2(path.c_str(), &impl->db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                        nullptr) != SQLITE_OK)
        impl->fail("cannot open the database");
    sqlite3_extended_result_codes(impl->db, 1);
    // busy_timeout first: the other pragmas and the migrations may wait for another connection.
    impl->exec("PRAGMA busy_timeout = 5000", "setting busy_timeout");
    // Only WAL is recorded in the file; a rollback file reads as SQLite's default, "delete".
    const bool file_in_wal = journal_mode_of(*impl) == "wal";
    const Journal wanted = journal ? *journal : (new_file || file_in_wal ? Journal::wal : Journal::rollback);
    if (wanted == Journal::rollback) {
        // TRUNCATE rather than DELETE: the -journal file is emptied after each commit, not
        // created and unlinked again. Leaving WAL needs the file to itself: another program
        // holding it rarely lets go within a busy timeout, so this is tried once, at once.
        std::string mode, why;
        if (file_in_wal) sqlite3_busy_timeout(impl->db, 0);
        try {
            Query q(*impl, "PRAGMA journal_mode = TRUNCATE");
            q.step();
            mode = q.text(0);
        } catch (const std::exception& e) {
            why = e.what();
        }
        sqlite3_busy_timeout(impl->db, 5000);
        if (mode != "truncate") {
            spdlog::warn("{}: stays in WAL journal mode, not rollback as configured: {}", path.string(),
                         why.empty() ? "SQLite kept '" + mode + "'" : why);
            if (const auto now = journal_mode_of(*impl); now != "wal")
                throw UserError(fmt::format("{}: in neither WAL nor rollback journal mode ('{}')", path.string(), now));
        }
    } else {
        Query q(*impl, "PRAGMA journal_mode = WAL");
        q.step();
        // The durability argument in docs/recorder.md holds only in WAL mode (a network
        // filesystem without shared memory refuses it).
        if (const auto mode = q.text(0); mode != "wal")
            throw UserError(fmt::format("{}: cannot use WAL journal mode (SQLite kept '{}'); put the database on a "
                                        "local filesystem",
                                        path.string(), mode));
    }
    impl->exec(durability == Durability::power ? "PRAGMA synchronous = FULL" : "PRAGMA synchronous = NORMAL",
               "setting synchronous");
    impl->exec("PRAGMA foreign_keys = ON", "enabling foreign keys");
    migrate(*impl);
    impl->insert_sample = impl->statement(
        "INSERT INTO samples (trial_id, channel_id, mono_ns, utc_ns, value, quality, id) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)");
    impl->insert_idle_sample = impl->statement(
        // Same parameter numbers as insert_sample (?1, the trial, unused): one binding loop serves both.
        "INSERT OR IGNORE INTO idle_samples (channel_id, mono_ns, utc_ns, value, quality) VALUES (?2, ?3, ?4, ?5, ?6)");
    Database opened(std::move(impl));
    opened.refresh_trial_table();  // a database from before version 4, or channels added by another program
    return opened;
}

int open_sqlite_read_only(const std::filesystem::path& path, sqlite3** db) {
    int rc = sqlite3_open_v2(path.c_str(), db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX, nullptr);
    if (rc != SQLITE_OK) return rc;
    // The open is lazy: the first read finds out whether the WAL index can be had.
    rc = sqlite3_exec(*db, "SELECT count(*) FROM sqlite_schema", nullptr, nullptr, nullptr);
    if ((rc & 0xff) != SQLITE_CANTOPEN) return SQLITE_OK;  // another failure shows at the caller's own first read
    std::error_code ec;
    const auto folder = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    if (std::filesystem::exists(path.string() + "-wal", ec) || ::access(folder.c_str(), W_OK) == 0) return rc;
    // Nothing can write here, and everything is in the file: read it as the immutable file it is.
    std::string uri = "file:";
    for (const char c : std::filesystem::absolute(path, ec).string()) {
        if (c == '%' || c == '?' || c == '#') uri += fmt::format("%{:02X}", static_cast<unsigned char>(c));
        else uri += c;
    }
    uri += "?immutable=1";
    sqlite3_close_v2(*db);
    *db = nullptr;
    return sqlite3_open_v2(uri.c_str(), db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX | SQLITE_OPEN_URI, nullptr);
}

bool is_sqlite_file(const std::filesystem::path& path) {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return false;
    std::array<char, 16> header{};
    const bool full = std::fread(header.data(), 1, header.size(), f) == header.size();
    std::fclose(f);
    return full && std::memcmp(header.data(), "SQLite format 3", 16) == 0;
}

Database Database::open_read_only(const std::filesystem::path& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0)
        throw UserError(fmt::format("{}: no such database ({})", path.string(), std::strerror(errno)));
    if (!S_ISREG(st.st_mode)) throw UserError(fmt::format("{}: not a regular file, so not a manikind database", path.string()));
    if (st.st_size == 0) throw UserError(fmt::format("{}: an empty file, not a manikind database", path.string()));
    // Identified through SQLite itself, never by opening the file outside it: closing any
    // descriptor of a file drops every POSIX lock this process holds on it, so a peek at the
    // header while the daemon's recorder has the database open (the interim results, the
    // console, the archive forwarder all open it read-only in the daemon) left the recorder's
    // locks gone; a plain `sqlite3` reader then took itself for the last connection,
    // checkpointed and deleted the live -wal (issue 60; SQLite's "How To Corrupt", 2.2.1).
    auto impl = std::make_unique<Impl>();
    impl->path = path;
    if (open_sqlite_read_only(path, &impl->db) != SQLITE_OK) impl->fail("cannot open the database to read");
    sqlite3_extended_result_codes(impl->db, 1);
    if (const int rc = sqlite3_exec(impl->db, "SELECT count(*) FROM sqlite_schema", nullptr, nullptr, nullptr);
        (rc & 0xff) == SQLITE_NOTADB)
        throw UserError(fmt::format("{}: not an SQLite database, so not a manikind database", path.string()));
    impl->exec("PRAGMA busy_timeout = 5000", "setting busy_timeout");
    int tables = 0;
    {
        Query q(*impl, "SELECT count(*) FROM sqlite_schema WHERE type = 'table' AND name IN ('campaigns', 'trials', 'samples', 'channels')");
        q.step();
        tables = static_cast<int>(q.integer(0));
    }
    const int version = user_version(*impl);
    if (tables != 4 || version < 1)
        throw UserError(fmt::format("{}: an SQLite database, but not a manikind one (no campaigns, trials, channels and samples "
                                    "tables): not opened",
                                    path.string()));
    if (version > latest_schema_version())
        throw UserError(fmt::format("{}: recorded by a newer manikind (schema {}; this program reads up to {}): use that "
                                    "version's manikin",
                                    path.string(), version, latest_schema_version()));
    if (version < latest_schema_version())
        throw UserError(fmt::format("{}: recorded by an older manikind (schema {}; this program reads {}): start manikind on it "
                                    "once (it upgrades the file, keeping every sample), then read it",
                                    path.string(), version, latest_schema_version()));
    return Database(std::move(impl));
}

const std::filesystem::path& Database::path() const { return impl_->path; }

int Database::schema_version() { return user_version(*impl_); }

void Database::set_busy_timeout(std::chrono::milliseconds timeout) {
    sqlite3_busy_timeout(impl_->db, static_cast<int>(timeout.count()));
}

std::string Database::journal_mode() { return journal_mode_of(*impl_); }

int Database::synchronous() {
    Query q(*impl_, "PRAGMA synchronous");
    q.step();
    return static_cast<int>(q.integer(0));
}

std::string Database::integrity_check() {
    Query q(*impl_, "PRAGMA integrity_check");
    std::string out;
    while (q.step()) out += (out.empty() ? "" : "\n") + q.text(0);
    return out;
}

std::int64_t Database::create_campaign(const std::string& name, const std::string& definition_json) {
    const std::int64_t now = utc_now_ns();
    Query q(*impl_, "INSERT INTO campaigns (name, definition_json, created_utc_ns) VALUES (?, ?, ?)");
    q.bind(name, definition_json, now);
    if (const int rc = q.step_code(); rc != SQLITE_DONE) {
        if (rc == SQLITE_CONSTRAINT_UNIQUE)
            throw UserError(fmt::format("{}: a campaign named '{}' already exists", impl_->path.string(), name));
        impl_->fail(fmt::format("creating campaign '{}'", name));
    }
    return sqlite3_last_insert_rowid(impl_->db);
}

std::optional<std::int64_t> Database::find_campaign(const std::string& name) {
    Query q(*impl_, "SELECT id FROM campaigns WHERE name = ?");
    q.bind(name);
    if (!q.step()) return std::nullopt;
    return q.integer(0);
}

namespace {
void expect_one_change(Database::Impl& impl, std::string_view table, std::int64_t id) {
    if (sqlite3_changes(impl.db) != 1)
        throw UserError(fmt::format("{}: no row with id {} in {}", impl.path.string(), id, table));
}
}  // namespace

void Database::set_campaign_state(std::int64_t campaign_id, const std::string& state) {
    Query(*impl_, "UPDATE campaigns SET state = ? WHERE id = ?").bind(state, campaign_id).run();
    expect_one_change(*impl_, "campaigns", campaign_id);
}

std::int64_t Database::add_case(std::int64_t campaign_id, const std::string& name, const std::string& conditions_json,
                                std::int64_t position) {
    Query(*impl_, "INSERT INTO cases (campaign_id, name, conditions_json, position) VALUES (?, ?, ?, ?)")
        .bind(campaign_id, name, conditions_json, position)
        .run();
    return sqlite3_last_insert_rowid(impl_->db);
}

std::int64_t Database::create_trial(std::int64_t campaign_id, std::int64_t case_id, std::int64_t replicate) {
    // 128 random bits from SQLite's PRNG (seeded from the OS), as 32 hex digits.
    Query(*impl_, "INSERT INTO trials (campaign_id, case_id, replicate, uuid) VALUES (?, ?, ?, lower(hex(randomblob(16))))")
        .bind(campaign_id, case_id, replicate)
        .run();
    return sqlite3_last_insert_rowid(impl_->db);
}

void Database::set_trial_state(std::int64_t trial_id, const std::string& state, const std::string& reason,
                               std::int64_t utc_ns) {
    const std::int64_t terminal = is_terminal_trial_state(state) ? 1 : 0;
    Query(*impl_,
          "UPDATE trials SET state = ?1, reason = ?2,"
          " started_utc_ns = CASE WHEN started_utc_ns IS NULL AND ?1 <> 'pending' THEN ?3 ELSE started_utc_ns END,"
          " ended_utc_ns = CASE WHEN ?4 THEN ?3 ELSE ended_utc_ns END"
          " WHERE id = ?5")
        .bind(state, reason, utc_ns, terminal, trial_id)
        .run();
    expect_one_change(*impl_, "trials", trial_id);
}

void Database::set_trial_steady(std::int64_t trial_id, std::int64_t mono_ns) {
    Query(*impl_, "UPDATE trials SET steady_from_mono_ns = ? WHERE id = ?").bind(mono_ns, trial_id).run();
    expect_one_change(*impl_, "trials", trial_id);
}

void Database::add_trial_flag(std::int64_t trial_id, std::int64_t flag_bits) {
    Query(*impl_, "UPDATE trials SET quality_flags = quality_flags | ? WHERE id = ?").bind(flag_bits, trial_id).run();
    expect_one_change(*impl_, "trials", trial_id);
}

int Database::mark_interrupted_trials(std::int64_t utc_ns) {
    Query(*impl_,
          // Never before the trial began, whatever clock the caller has (a virtual clock runs ahead
          // of the wall clock; issue 60 found interrupted trials ending before they started).
          "UPDATE trials SET state = 'interrupted', reason = 'daemon restarted', ended_utc_ns = max(?1, coalesce(started_utc_ns, ?1))"
          " WHERE state NOT IN ('done', 'aborted', 'interrupted', 'failed')")
        .bind(utc_ns)
        .run();
    return sqlite3_changes(impl_->db);
}

int Database::mark_interrupted_campaigns() {
    // 'created': killed between creating the campaign and its first trial.
    Query(*impl_, "UPDATE campaigns SET state = 'interrupted' WHERE state IN ('created', 'running')").run();
    return sqlite3_changes(impl_->db);
}

std::int64_t Database::device_id(const std::string& name, const std::string& kind, const std::string& address) {
    Query q(*impl_,
            "INSERT INTO devices (name, kind, address) VALUES (?, ?, ?)"
            " ON CONFLICT (name) DO UPDATE SET kind = excluded.kind, address = excluded.address RETURNING id");
    q.bind(name, kind, address);
    if (!q.step()) impl_->fail(fmt::format("registering device '{}'", name));
    const std::int64_t id = q.integer(0);
    q.run();  // finish the statement so the upsert is complete before reset
    return id;
}

void Database::refresh_trial_table() {
    const std::string wanted = trial_table_sql(impl_->db);
    {
        Query q(*impl_, "SELECT sql FROM sqlite_schema WHERE type = 'view' AND name = 'trial_table'");
        if (q.step() && q.text(0) == wanted) return;  // current: no write
    }
    // A savepoint, not BEGIN: a caller may already be inside a transaction.
    impl_->exec("SAVEPOINT trial_table", "replacing the view trial_table");
    if (sqlite3_exec(impl_->db, "DROP VIEW IF EXISTS trial_table", nullptr, nullptr, nullptr) != SQLITE_OK ||
        sqlite3_exec(impl_->db, wanted.c_str(), nullptr, nullptr, nullptr) != SQLITE_OK ||
        sqlite3_exec(impl_->db, "RELEASE trial_table", nullptr, nullptr, nullptr) != SQLITE_OK) {
        const int code = sqlite3_errcode(impl_->db), sys_errno = sqlite3_system_errno(impl_->db);
        const std::string message = sqlite3_errmsg(impl_->db);
        sqlite3_exec(impl_->db, "ROLLBACK TO trial_table; RELEASE trial_table", nullptr, nullptr, nullptr);
        impl_->fail_with(code, sys_errno, "replacing the view trial_table", message);
    }
}

void Database::atomically(const std::function<void()>& body) {
    // A savepoint: nests inside a caller's transaction, and is one transaction on its own.
    impl_->exec("SAVEPOINT atomically", "starting a transaction");
    try {
        body();
        if (sqlite3_exec(impl_->db, "RELEASE atomically", nullptr, nullptr, nullptr) != SQLITE_OK) impl_->fail("committing");
    } catch (...) {
        sqlite3_exec(impl_->db, "ROLLBACK TO atomically; RELEASE atomically", nullptr, nullptr, nullptr);
        throw;
    }
}

std::int64_t Database::channel_id(std::int64_t device_id, const std::string& name, const std::string& unit) {
    {
        Query q(*impl_, "SELECT id, unit FROM channels WHERE device_id = ? AND name = ?");
        q.bind(device_id, name);
        if (q.step()) {
            if (const auto stored = q.text(1); stored != unit)
                throw UserError(fmt::format("{}: channel '{}' of device {} is recorded in '{}', now configured as '{}'; "
                                            "give the channel a new name",
                                            impl_->path.string(), name, device_id, stored, unit));
            return q.integer(0);
        }
    }
    Query(*impl_, "INSERT INTO channels (device_id, name, unit) VALUES (?, ?, ?)").bind(device_id, name, unit).run();
    // trial_table is not rebuilt here: a daemon registers its 157 channels one by one as their
    // first samples arrive, and a schema change per channel cost a busy daemon a fifth of a core
    // (every connection re-prepares). The daemon refreshes it when a trial ends.
    return sqlite3_last_insert_rowid(impl_->db);
}

void Database::check_sample_keys_here() {
    // Not toggled per transaction: a flag pragma expires every prepared statement of the
    // connection, and re-preparing after each commit made the demo 40 % slower in wall time.
    impl_->exec("PRAGMA foreign_keys = OFF", "leaving the samples' foreign keys to insert_samples");
}

std::size_t Database::remove_already_stored(std::vector<SampleRow>& rows) {
    std::unordered_map<std::int64_t, std::int64_t> earliest_by_trial;
    for (const auto& r : rows)
        if (r.trial_id != 0) {
            auto [it, fresh] = earliest_by_trial.try_emplace(r.trial_id, r.mono_ns);
            if (!fresh) it->second = std::min(it->second, r.mono_ns);
        }
    struct Key {
        std::int64_t trial, channel, mono_ns;
        bool operator==(const Key&) const = default;
    };
    struct KeyHash {
        std::size_t operator()(const Key& k) const noexcept {
            return std::hash<std::int64_t>{}(k.mono_ns * 1'000'003 + k.channel * 7919 + k.trial);
        }
    };
    std::unordered_set<Key, KeyHash> stored;
    for (const auto& [trial, earliest] : earliest_by_trial) {
        Query q(*impl_, "SELECT channel_id, mono_ns FROM samples WHERE id >= ?1 AND id < ?2 AND mono_ns >= ?3");
        q.bind(trial_id_begin(trial), trial_id_end(trial), earliest);
        while (q.step()) stored.insert({trial, q.integer(0), q.integer(1)});
    }
    const auto before = rows.size();
    std::erase_if(rows, [&](const SampleRow& r) { return r.trial_id != 0 && stored.count({r.trial_id, r.channel_id, r.mono_ns}); });
    return before - rows.size();
}

namespace {

// The tail of a trial's rows (Impl::TrialTail), current as stored.
Database::Impl::TrialTail& trial_tail(Database::Impl& impl, std::int64_t trial_id) {
    // Inside insert_samples' transaction, which holds the write lock: nobody else can append.
    const auto first = trial_id_begin(trial_id);
    std::int64_t stored_end = first;
    {
        Query q(impl, "SELECT max(id) FROM samples WHERE id >= ?1 AND id < ?2");
        q.bind(first, trial_id_end(trial_id));
        if (q.step() && q.optional_integer(0)) stored_end = *q.optional_integer(0) + 1;
    }
    auto& tail = impl.trial_tails[trial_id];
    if (tail.next_id == stored_end) return tail;
    tail.next_id = stored_end;
    tail.newest_mono_ns.clear();
    Query q(impl, "SELECT channel_id, max(mono_ns) FROM samples WHERE id >= ?1 AND id < ?2 GROUP BY channel_id");
    q.bind(first, trial_id_end(trial_id));
    while (q.step()) tail.newest_mono_ns[q.integer(0)] = q.integer(1);
    return tail;
}

// Whether this reading (trial, channel, time) is stored already.
bool stored_in_trial(Database::Impl& impl, const SampleRow& r) {
    Query q(impl, "SELECT 1 FROM samples WHERE id >= ?1 AND id < ?2 AND channel_id = ?3 AND mono_ns = ?4 LIMIT 1");
    q.bind(trial_id_begin(r.trial_id), trial_id_end(r.trial_id), r.channel_id, r.mono_ns);
    return q.step();
}

}  // namespace

std::size_t Database::insert_samples(std::span<const SampleRow> rows) {
    // The foreign keys of samples, checked against the known ids (two hash lookups a row) on
    // every connection; on the Recorder's, which does nothing else, SQLite's own checks (two
    // b-tree searches a row) are off (check_sample_keys_here). A row naming a trial or channel
    // that does not exist fails its whole transaction, and nothing is stored.
    const auto require = [&](std::unordered_set<std::int64_t>& known, std::int64_t id, std::string_view sql,
                             const char* what) {
        if (known.count(id)) return;
        Query q(*impl_, sql);
        q.bind(id);
        if (!q.step())
            throw UserError(fmt::format("{}: inserting samples: {} {} does not exist (ids come from {})", impl_->path.string(),
                                        what, id, what == std::string_view("trial") ? "create_trial" : "channel_id"));
        known.insert(id);
    };
    for (const auto& r : rows) {
        if (r.trial_id != 0) require(impl_->known_trials, r.trial_id, "SELECT 1 FROM trials WHERE id = ?", "trial");
        require(impl_->known_channels, r.channel_id, "SELECT 1 FROM channels WHERE id = ?", "channel");
    }
    Transaction tx(*impl_);
    std::size_t duplicates = 0;
    // A failed transaction leaves the tails ahead of what is stored: forget them.
    struct ForgetTailsOnThrow {
        Impl& impl;
        bool armed = true;
        ~ForgetTailsOnThrow() {
            if (armed) impl.trial_tails.clear();
        }
    } forget{*impl_};
    Impl::TrialTail* tail = nullptr;
    std::int64_t tail_trial = 0;
    // Every parameter is bound for every row, so no clear_bindings; reset before the check so
    // the statement is reusable whatever happens.
    for (const auto& r : rows) {
        if (r.trial_id != 0) {
            if (!tail || tail_trial != r.trial_id) {
                tail = &trial_tail(*impl_, r.trial_id);
                tail_trial = r.trial_id;
            }
            // A re-sent reading: the same channel and time as one stored. Each channel's readings
            // come in time order, so only a time not after the channel's newest needs a look
            // (a scan of the trial's range, which sees this transaction's rows too).
            auto [newest, fresh] = tail->newest_mono_ns.try_emplace(r.channel_id, r.mono_ns);
            if (!fresh) {
                if (r.mono_ns <= newest->second && stored_in_trial(*impl_, r)) {
                    ++duplicates;
                    continue;
                }
                newest->second = std::max(newest->second, r.mono_ns);
            }
            if (tail->next_id >= trial_id_end(r.trial_id))
                throw UserError(fmt::format("{}: inserting samples: trial {} already holds 2^36 samples",
                                            impl_->path.string(), r.trial_id));
            sqlite3_bind_int64(impl_->insert_sample, 7, tail->next_id++);
        }
        sqlite3_stmt* s = r.trial_id == 0 ? impl_->insert_idle_sample : impl_->insert_sample;
        sqlite3_bind_int64(s, 1, r.trial_id);
        sqlite3_bind_int64(s, 2, r.channel_id);
        sqlite3_bind_int64(s, 3, r.mono_ns);
        sqlite3_bind_int64(s, 4, r.utc_ns);
        if (std::isnan(r.value))
            sqlite3_bind_null(s, 5);
        else
            sqlite3_bind_double(s, 5, r.value);
        sqlite3_bind_int64(s, 6, r.quality);
        const int rc = sqlite3_step(s);
        sqlite3_reset(s);
        if (rc != SQLITE_DONE) impl_->fail("inserting samples");
        // The idle log's OR IGNORE: a re-sent reading must not fail the other rows of its transaction.
        if (r.trial_id == 0 && sqlite3_changes(impl_->db) == 0) ++duplicates;
    }
    tx.commit();
    forget.armed = false;
    return duplicates;
}


std::int64_t Database::add_event(std::optional<std::int64_t> trial_id, std::int64_t mono_ns, std::int64_t utc_ns,
                                 const std::string& severity, const std::string& kind, const std::string& message) {
    Query(*impl_, "INSERT INTO events (trial_id, mono_ns, utc_ns, severity, kind, message) VALUES (?, ?, ?, ?, ?, ?)")
        .bind(trial_id, mono_ns, utc_ns, severity, kind, message)
        .run();
    return sqlite3_last_insert_rowid(impl_->db);
}

std::int64_t Database::add_note(const NoteRow& note) {
    Query(*impl_, "INSERT INTO notes (campaign_id, trial_id, utc_ns, author, kind, text) VALUES (?, ?, ?, ?, ?, ?)")
        .bind(note.campaign_id, note.trial_id, note.utc_ns, note.author, note.kind, note.text)
        .run();
    return sqlite3_last_insert_rowid(impl_->db);
}

std::vector<NoteRow> Database::notes(std::int64_t campaign_id) {
    Query q(*impl_, "SELECT id, campaign_id, trial_id, utc_ns, author, kind, text FROM notes WHERE campaign_id = ? ORDER BY utc_ns, id");
    q.bind(campaign_id);
    std::vector<NoteRow> out;
    while (q.step()) out.push_back({q.integer(0), q.integer(1), q.optional_integer(2), q.integer(3), q.text(4), q.text(5), q.text(6)});
    return out;
}

std::int64_t Database::store_result(std::int64_t campaign_id, const std::string& json, std::int64_t utc_ns) {
    Query(*impl_, "INSERT INTO results (campaign_id, computed_utc_ns, json) VALUES (?, ?, ?)")
        .bind(campaign_id, utc_ns, json)
        .run();
    return sqlite3_last_insert_rowid(impl_->db);
}

std::int64_t Database::store_twin_version(const std::string& name, std::int64_t version, const std::string& toml) {
    {
        Query q(*impl_, "SELECT id, toml FROM twin_versions WHERE name = ? AND version = ?");
        q.bind(name, version);
        if (q.step()) {
            if (q.text(1) != toml)
                throw UserError(fmt::format("{}: twin version '{}' v{} is already stored with different content; "
                                            "store the change as a new version",
                                            impl_->path.string(), name, version));
            return q.integer(0);
        }
    }
    const std::int64_t now = utc_now_ns();
    Query(*impl_, "INSERT INTO twin_versions (name, version, toml, created_utc_ns) VALUES (?, ?, ?, ?)")
        .bind(name, version, toml, now)
        .run();
    return sqlite3_last_insert_rowid(impl_->db);
}

std::string Setup::sha256() const {
    // Fields joined by NUL (absent from TOML, JSON and the names), so no two set-ups share a text.
    std::string joined;
    for (const std::string* f : {&lab_name, &chamber, &manikin, &calibration_json, &config_toml}) {
        joined += *f;
        joined += '\0';
    }
    return sha256_hex(joined);
}

std::int64_t Database::record_setup(const Setup& setup, std::int64_t utc_ns) {
    const std::string key = setup.sha256();
    Query(*impl_,
          "INSERT INTO setups (sha256, lab_name, chamber, manikin, calibration_json, config_toml, first_used_utc_ns)"
          " VALUES (?, ?, ?, ?, ?, ?, ?) ON CONFLICT (sha256) DO NOTHING")
        .bind(key, setup.lab_name, setup.chamber, setup.manikin, setup.calibration_json, setup.config_toml, utc_ns)
        .run();
    Query q(*impl_, "SELECT id FROM setups WHERE sha256 = ?");
    q.bind(key);
    q.step();
    return q.integer(0);
}

void Database::set_trial_setup(std::int64_t trial_id, std::int64_t setup_id) {
    Query(*impl_, "UPDATE trials SET setup_id = ? WHERE id = ?").bind(setup_id, trial_id).run();
}

std::optional<SetupRow> Database::setup(std::int64_t setup_id) {
    Query q(*impl_,
            "SELECT id, sha256, first_used_utc_ns, lab_name, chamber, manikin, calibration_json, config_toml"
            " FROM setups WHERE id = ?");
    q.bind(setup_id);
    if (!q.step()) return std::nullopt;
    SetupRow row;
    row.id = q.integer(0);
    row.sha256 = q.text(1);
    row.first_used_utc_ns = q.integer(2);
    row.setup = {q.text(3), q.text(4), q.text(5), q.text(6), q.text(7)};
    return row;
}

std::optional<std::string> Database::twin_version_toml(const std::string& name, std::int64_t version) {
    Query q(*impl_, "SELECT toml FROM twin_versions WHERE name = ? AND version = ?");
    q.bind(name, version);
    if (!q.step()) return std::nullopt;
    return q.text(0);
}

std::optional<std::string> Database::latest_twin_version() {
    Query q(*impl_, "SELECT name, version FROM twin_versions ORDER BY created_utc_ns DESC, id DESC LIMIT 1");
    if (!q.step()) return std::nullopt;
    return q.text(0) + " v" + std::to_string(q.integer(1));
}

std::vector<CampaignRow> Database::campaigns() {
    Query q(*impl_, "SELECT id, name, definition_json, created_utc_ns, state FROM campaigns ORDER BY id");
    std::vector<CampaignRow> out;
    while (q.step()) out.push_back({q.integer(0), q.text(1), q.text(2), q.integer(3), q.text(4)});
    return out;
}

std::vector<CaseRow> Database::cases(std::int64_t campaign_id) {
    Query q(*impl_,
            "SELECT id, campaign_id, name, conditions_json, position FROM cases WHERE campaign_id = ?"
            " ORDER BY position, id");
    q.bind(campaign_id);
    std::vector<CaseRow> out;
    while (q.step()) out.push_back({q.integer(0), q.integer(1), q.text(2), q.text(3), q.integer(4)});
    return out;
}

namespace {
constexpr const char* trial_columns =
    "SELECT id, campaign_id, case_id, replicate, state, reason, started_utc_ns, ended_utc_ns, steady_from_mono_ns,"
    " quality_flags, uuid, setup_id FROM trials ";

TrialRow read_trial(const Query& q) {
    return {q.integer(0),          q.integer(1),          q.integer(2),          q.integer(3), q.text(4), q.text(5),
            q.optional_integer(6), q.optional_integer(7), q.optional_integer(8), q.integer(9), q.text(10),
            q.optional_integer(11)};
}
}  // namespace

std::vector<TrialRow> Database::trials(std::int64_t campaign_id) {
    static const std::string sql = std::string(trial_columns) + "WHERE campaign_id = ? ORDER BY id";
    Query q(*impl_, sql);
    q.bind(campaign_id);
    std::vector<TrialRow> out;
    while (q.step()) out.push_back(read_trial(q));
    return out;
}

std::optional<TrialRow> Database::trial(std::int64_t trial_id) {
    static const std::string sql = std::string(trial_columns) + "WHERE id = ?";
    Query q(*impl_, sql);
    q.bind(trial_id);
    if (!q.step()) return std::nullopt;
    return read_trial(q);
}

std::vector<ChannelRow> Database::channels() {
    Query q(*impl_,
            "SELECT c.id, c.device_id, d.name, c.name, c.unit FROM channels c JOIN devices d ON d.id = c.device_id"
            " ORDER BY d.name, c.name");
    std::vector<ChannelRow> out;
    while (q.step()) out.push_back({q.integer(0), q.integer(1), q.text(2), q.text(3), q.text(4)});
    return out;
}

std::vector<SampleRow> Database::samples(std::int64_t trial_id, std::int64_t channel_id) {
    Query q(*impl_,
            "SELECT mono_ns, utc_ns, value, quality FROM samples WHERE id >= ?1 AND id < ?2 AND channel_id = ?3"
            " ORDER BY mono_ns");
    q.bind(trial_id_begin(trial_id), trial_id_end(trial_id), channel_id);
    std::vector<SampleRow> out;
    while (q.step())
        out.push_back({trial_id, channel_id, q.integer(0), q.integer(1), q.real(2), static_cast<std::uint8_t>(q.integer(3))});
    return out;
}

void Database::for_each_trial_sample(std::int64_t trial_id, const std::function<void(const SampleRow&)>& visit) {
    // Read in stored order and sorted here, not by ORDER BY: SQLite's sorter spills a trial
    // (180 000 rows) to temporary files beyond its 2 MB cache, which made the demo 20 % slower.
    // Stored order is already time order per device, so the sort mostly orders channels
    // within an instant. Memory: one trial.
    std::vector<SampleRow> rows;
    {
        // Sized once: a trial's ids run from its range's start without gaps but for rows a
        // failed write left out, so the last id bounds the count, found by two key lookups.
        // Growing by doubling instead held the old and the new buffer at once (26 MB for a
        // trial of 182 000 rows), the peak of an export.
        Query last(*impl_, "SELECT max(id) FROM samples WHERE id >= ?1 AND id < ?2");
        last.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
        if (last.step() && last.optional_integer(0)) {
            const auto span = *last.optional_integer(0) - trial_id_begin(trial_id) + 1;
            if (span > 0 && span < (std::int64_t{1} << 28)) rows.reserve(static_cast<std::size_t>(span));
        }
    }
    {
        Query q(*impl_, "SELECT mono_ns, channel_id, utc_ns, value, quality FROM samples WHERE id >= ?1 AND id < ?2");
        q.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
        while (q.step())
            rows.push_back({trial_id, q.integer(1), q.integer(0), q.integer(2), q.real(3), static_cast<std::uint8_t>(q.integer(4))});
    }
    const auto by_time = [](const SampleRow& a, const SampleRow& b) {
        return a.mono_ns != b.mono_ns ? a.mono_ns < b.mono_ns : a.channel_id < b.channel_id;
    };
    if (!std::is_sorted(rows.begin(), rows.end(), by_time)) std::sort(rows.begin(), rows.end(), by_time);
    for (const auto& row : rows) visit(row);
}

std::vector<SampleRow> Database::idle_samples(std::int64_t channel_id, std::int64_t since_utc_ns) {
    // Keyed (utc_ns, channel_id): the time bound is the key range, the channel a filter.
    Query q(*impl_, "SELECT mono_ns, utc_ns, value, quality FROM idle_samples WHERE utc_ns >= ? AND channel_id = ? ORDER BY utc_ns");
    q.bind(since_utc_ns, channel_id);
    std::vector<SampleRow> out;
    while (q.step())
        out.push_back({0, channel_id, q.integer(0), q.integer(1), q.real(2), static_cast<std::uint8_t>(q.integer(3))});
    return out;
}

std::optional<std::int64_t> Database::newest_idle_utc_ns() {
    Query q(*impl_, "SELECT max(utc_ns) FROM idle_samples");
    q.step();
    return q.optional_integer(0);
}

std::optional<std::int64_t> Database::newest_utc_ns() {
    // Three key lookups and a scan of the (small) events table: samples are a rowid range per
    // trial in trial order, the idle log is keyed by utc_ns first.
    std::optional<std::int64_t> newest = newest_idle_utc_ns();
    for (const char* sql : {"SELECT utc_ns FROM samples ORDER BY id DESC LIMIT 1", "SELECT max(utc_ns) FROM events"}) {
        Query q(*impl_, sql);
        if (!q.step()) continue;
        if (const auto v = q.optional_integer(0); v && (!newest || *v > *newest)) newest = v;
    }
    return newest;
}

std::int64_t Database::idle_sample_count() {
    Query q(*impl_, "SELECT count(*) FROM idle_samples");
    q.step();
    return q.integer(0);
}

Database::RowMark Database::row_mark() {
    RowMark mark;
    {
        Query q(*impl_, "SELECT max(id) FROM samples");
        q.step();
        mark.sample_id = q.optional_integer(0).value_or(-1);
    }
    mark.idle_rows = idle_sample_count();
    return mark;
}

std::int64_t Database::rows_since(const RowMark& mark) {
    std::int64_t n = 0;
    {
        Query q(*impl_, "SELECT count(*) FROM samples WHERE id > ?1");
        q.bind(mark.sample_id);
        q.step();
        n += q.integer(0);
    }
    return n + idle_sample_count() - mark.idle_rows;
}

std::int64_t Database::sample_count(std::int64_t trial_id) {
    Query q(*impl_, "SELECT count(*) FROM samples WHERE id >= ?1 AND id < ?2");
    q.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
    q.step();
    return q.integer(0);
}

std::optional<std::int64_t> Database::last_sample_mono_ns(std::int64_t trial_id) {
    Query q(*impl_, "SELECT max(mono_ns) FROM samples WHERE id >= ?1 AND id < ?2");
    q.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
    if (!q.step()) return std::nullopt;
    return q.optional_integer(0);
}

std::vector<EventRow> Database::events(std::optional<std::int64_t> trial_id) {
    // Two statements rather than "?1 IS NULL OR trial_id = ?1", which the planner cannot
    // answer from events_by_trial_time.
    Query q = trial_id ? Query(*impl_, "SELECT id, trial_id, mono_ns, utc_ns, severity, kind, message FROM events"
                                       " WHERE trial_id = ? ORDER BY mono_ns, id")
                       : Query(*impl_, "SELECT id, trial_id, mono_ns, utc_ns, severity, kind, message FROM events"
                                       " ORDER BY mono_ns, id");
    if (trial_id) q.bind(*trial_id);
    std::vector<EventRow> out;
    while (q.step())
        out.push_back({q.integer(0), q.optional_integer(1), q.integer(2), q.integer(3), q.text(4), q.text(5), q.text(6)});
    return out;
}

std::optional<ResultRow> Database::latest_result(std::int64_t campaign_id) {
    Query q(*impl_,
            "SELECT id, campaign_id, computed_utc_ns, json FROM results WHERE campaign_id = ?"
            " ORDER BY computed_utc_ns DESC, id DESC LIMIT 1");
    q.bind(campaign_id);
    if (!q.step()) return std::nullopt;
    return ResultRow{q.integer(0), q.integer(1), q.integer(2), q.text(3)};
}

}  // namespace manikind::recorder
