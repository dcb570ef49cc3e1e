// The recording database's schema: each migration's SQL text, oldest first (Database::open applies
// the ones a file lacks: database_open.cpp), and the analysts' view trial_table, rebuilt for the
// channels stored now. docs/recorder.md, "Schema" and "Migrations".
#include "store/database_impl.hpp"

#include <array>
#include <span>
#include <string>

#include <fmt/core.h>

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

}  // namespace

// Append only: a released migration is never edited, a change is a new entry.
constexpr std::array<const char*, 9> all_migrations{migration_1, migration_2, migration_3, migration_4, migration_5,
                                                    migration_6, migration_7, migration_8, migration_9};

std::span<const char* const> Database::migrations() { return all_migrations; }
int Database::latest_schema_version() { return static_cast<int>(all_migrations.size()); }

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

}  // namespace manikind::recorder
