#include "archive/pg_schema.hpp"

#include <array>
#include <string>

#include <fmt/core.h>

#include "base/user_error.hpp"

namespace manikind::archive {
namespace {

// Version 1. Every table's key is made of names that mean the same in every lab (lab id, campaign
// name, trial UUID, device and channel names), never a SQLite file's row ids, so the same row
// pushed twice, or from a copy of the file, lands on the same key. Times are integers in ns as in
// the recorder. samples carries device and channel by name: the archive has no channel ids to
// keep in step with each lab's.
constexpr const char* migration_1 = R"sql(
CREATE TABLE labs (
    lab_id text PRIMARY KEY,
    name text NOT NULL,
    first_push_utc_ns bigint NOT NULL
);
CREATE TABLE campaigns (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    campaign_name text NOT NULL,
    definition_json text NOT NULL,
    created_utc_ns bigint NOT NULL,
    state text NOT NULL,
    PRIMARY KEY (lab_id, campaign_name)
);
CREATE TABLE trials (
    trial_uuid text PRIMARY KEY CHECK (trial_uuid ~ '^[0-9a-f]{32}$'),
    lab_id text NOT NULL,
    campaign_name text NOT NULL,
    case_name text NOT NULL,
    replicate integer NOT NULL,
    state text NOT NULL,
    reason text NOT NULL,
    started_utc_ns bigint,
    ended_utc_ns bigint,
    conditions_json text NOT NULL,
    FOREIGN KEY (lab_id, campaign_name) REFERENCES campaigns (lab_id, campaign_name)
);
CREATE INDEX trials_by_campaign ON trials (lab_id, campaign_name);
CREATE TABLE channels (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    device text NOT NULL,
    channel text NOT NULL,
    unit text NOT NULL,
    PRIMARY KEY (lab_id, device, channel)
);
CREATE TABLE samples (
    trial_uuid text NOT NULL REFERENCES trials (trial_uuid),
    device text NOT NULL,
    channel text NOT NULL,
    mono_ns bigint NOT NULL,
    utc_ns bigint NOT NULL,
    value double precision,
    quality smallint NOT NULL,
    PRIMARY KEY (trial_uuid, device, channel, mono_ns)
);
CREATE TABLE events (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    trial_uuid text REFERENCES trials (trial_uuid),
    mono_ns bigint NOT NULL,
    utc_ns bigint NOT NULL,
    severity text NOT NULL,
    kind text NOT NULL,
    message text NOT NULL
);
-- An event has no name beyond its file: it is the same event when lab, trial, both clocks, kind
-- and text agree. md5(message): a long message must not exceed a b-tree entry's size.
CREATE UNIQUE INDEX events_identity ON events (lab_id, coalesce(trial_uuid, ''), utc_ns, mono_ns, kind, md5(message));
-- How far each lab has sent. samples: one row per trial (scope = trial UUID), last_key the
-- SQLite key (mono_ns, channel id) of the last row committed here; complete once a terminal
-- trial is sent in full. terminal_pass: this pass began after the trial had ended (see forwarder).
CREATE TABLE forward_progress (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    source_table text NOT NULL,
    scope text NOT NULL,
    last_mono_ns bigint,
    last_channel_id bigint,
    rows_sent bigint NOT NULL DEFAULT 0,
    terminal_pass boolean NOT NULL DEFAULT false,
    complete boolean NOT NULL DEFAULT false,
    updated_utc_ns bigint NOT NULL,
    PRIMARY KEY (lab_id, source_table, scope)
);
)sql";

// Version 2: what version 1 left in the lab's file (docs/archive.md). results and twin_versions
// have no name beyond their content: results are keyed by campaign, computation time and an md5
// of the JSON (as events: a long text must not exceed a b-tree entry), twin versions by their
// own (name, version), which the recorder keeps immutable. idle_samples is the idle log by
// device and channel name; its progress row (scope '') keys on the SQLite key (utc_ns, channel
// id), hence last_utc_ns. trial_steps: one row per time step of a trial for analysts.
constexpr const char* migration_2 = R"sql(
CREATE TABLE devices (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    device text NOT NULL,
    kind text NOT NULL,
    transport text NOT NULL,
    PRIMARY KEY (lab_id, device)
);
CREATE TABLE results (
    lab_id text NOT NULL,
    campaign_name text NOT NULL,
    computed_utc_ns bigint NOT NULL,
    json text NOT NULL,
    FOREIGN KEY (lab_id, campaign_name) REFERENCES campaigns (lab_id, campaign_name)
);
CREATE UNIQUE INDEX results_identity ON results (lab_id, campaign_name, computed_utc_ns, md5(json));
CREATE TABLE twin_versions (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    twin_name text NOT NULL,
    version bigint NOT NULL,
    toml text NOT NULL,
    created_utc_ns bigint NOT NULL,
    PRIMARY KEY (lab_id, twin_name, version)
);
CREATE TABLE idle_samples (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    device text NOT NULL,
    channel text NOT NULL,
    utc_ns bigint NOT NULL,
    value double precision,
    quality smallint NOT NULL,
    PRIMARY KEY (lab_id, device, channel, utc_ns)
);
ALTER TABLE forward_progress ADD COLUMN last_utc_ns bigint;
CREATE VIEW trial_steps AS
SELECT trial_uuid, mono_ns, min(utc_ns) AS utc_ns, count(*) AS n_channels,
       jsonb_object_agg(device || '.' || channel, value) AS channel_values
FROM samples GROUP BY trial_uuid, mono_ns;
)sql";

// Version 3: the set-up each trial ran with (the recorder's schema version 7): lab, chamber,
// manikin, the calibration (Type B specs, register maps with probe scaling) and the configuration
// text, once per lab and SHA-256. The hash is over the recorder's text, so the JSON stays text.
constexpr const char* migration_3 = R"sql(
CREATE TABLE setups (
    lab_id text NOT NULL REFERENCES labs (lab_id),
    setup_sha256 text NOT NULL CHECK (setup_sha256 ~ '^[0-9a-f]{64}$'),
    lab_name text NOT NULL,
    chamber text NOT NULL,
    manikin text NOT NULL,
    calibration_json text NOT NULL,
    config_toml text NOT NULL,
    first_used_utc_ns bigint NOT NULL,
    PRIMARY KEY (lab_id, setup_sha256)
);
ALTER TABLE trials ADD COLUMN setup_sha256 text;
ALTER TABLE trials ADD FOREIGN KEY (lab_id, setup_sha256) REFERENCES setups (lab_id, setup_sha256);
CREATE VIEW trial_setups AS
SELECT t.trial_uuid, t.lab_id, t.campaign_name, t.case_name, t.replicate, s.setup_sha256, s.chamber, s.manikin,
       s.calibration_json::jsonb AS calibration, s.config_toml
FROM trials t LEFT JOIN setups s ON s.lab_id = t.lab_id AND s.setup_sha256 = t.setup_sha256;
)sql";

// Version 4: the lab notebook (recorder schema v9): notes by campaign name and, when about a trial,
// its UUID; their identity is their content (a note is never edited), so a push repeats none.
constexpr const char* migration_4 = R"sql(
CREATE TABLE notes (
    lab_id text NOT NULL,
    campaign_name text NOT NULL,
    trial_uuid text REFERENCES trials (trial_uuid),
    utc_ns bigint NOT NULL,
    author text NOT NULL,
    kind text NOT NULL,
    text text NOT NULL,
    FOREIGN KEY (lab_id, campaign_name) REFERENCES campaigns (lab_id, campaign_name)
);
CREATE UNIQUE INDEX notes_identity ON notes (lab_id, campaign_name, coalesce(trial_uuid, ''), utc_ns, author, kind, md5(text));
)sql";

// Version 5: samples keyed by integers (issue 36: the key of three text columns, a foreign-key
// check per row and ON CONFLICT on every row made a push 18.8x slower than a plain COPY). Each
// trial and channel gets an integer key of the archive's own (identity columns, filled for the
// rows already there); sample_rows holds (trial_key, mono_ns, channel_key), in the order a push
// sends them, with no foreign key: the push checks the trial once per chunk. `samples` stays, as a
// view with the names, for every reader (pull, trial_steps, a person's psql).
constexpr const char* migration_5 = R"sql(
ALTER TABLE trials ADD COLUMN trial_key integer GENERATED ALWAYS AS IDENTITY;
ALTER TABLE trials ADD CONSTRAINT trials_trial_key UNIQUE (trial_key);
ALTER TABLE channels ADD COLUMN channel_key integer GENERATED ALWAYS AS IDENTITY;
ALTER TABLE channels ADD CONSTRAINT channels_channel_key UNIQUE (channel_key);
CREATE TABLE sample_rows (
    trial_key integer NOT NULL,
    mono_ns bigint NOT NULL,
    channel_key integer NOT NULL,
    utc_ns bigint NOT NULL,
    value double precision,
    quality smallint NOT NULL,
    PRIMARY KEY (trial_key, mono_ns, channel_key)
);
INSERT INTO sample_rows (trial_key, mono_ns, channel_key, utc_ns, value, quality)
SELECT t.trial_key, s.mono_ns, c.channel_key, s.utc_ns, s.value, s.quality
FROM samples s JOIN trials t ON t.trial_uuid = s.trial_uuid
JOIN channels c ON c.lab_id = t.lab_id AND c.device = s.device AND c.channel = s.channel;
DROP VIEW trial_steps;
DROP TABLE samples;
CREATE VIEW samples AS
SELECT t.trial_uuid, c.device, c.channel, s.mono_ns, s.utc_ns, s.value, s.quality
FROM sample_rows s JOIN trials t ON t.trial_key = s.trial_key JOIN channels c ON c.channel_key = s.channel_key;
CREATE VIEW trial_steps AS
SELECT trial_uuid, mono_ns, min(utc_ns) AS utc_ns, count(*) AS n_channels,
       jsonb_object_agg(device || '.' || channel, value) AS channel_values
FROM samples GROUP BY trial_uuid, mono_ns;
)sql";

constexpr std::array<const char*, 5> all_migrations{migration_1, migration_2, migration_3, migration_4, migration_5};

// Any fixed number: the key of the lock pushers take while migrating.
constexpr const char* migration_lock_sql = "SELECT pg_advisory_xact_lock(7419001)";

}  // namespace

std::span<const char* const> pg_migrations() { return all_migrations; }
int pg_latest_schema_version() { return static_cast<int>(all_migrations.size()); }

int migrate_archive(PgConnection& pg) {
    const int latest = pg_latest_schema_version();
    for (;;) {
        pg.exec("BEGIN");
        try {
            pg.exec(migration_lock_sql);
            pg.exec("CREATE TABLE IF NOT EXISTS schema_version (version integer NOT NULL)");
            auto current = pg.exec("SELECT coalesce(max(version), 0) FROM schema_version");
            const auto version = static_cast<int>(current.int64(0, 0));
            if (version > latest) {
                throw UserError(fmt::format("archive {} has schema version {}, newer than this program's {}: "
                                            "update manikin",
                                            pg.describe(), version, latest),
                                "archive_refused", ExitStatus::refused);
            }
            if (version == latest) {
                pg.exec("COMMIT");
                return version;
            }
            pg.exec_script(all_migrations[static_cast<std::size_t>(version)]);
            pg.exec("DELETE FROM schema_version");
            pg.exec("INSERT INTO schema_version (version) VALUES ($1)", {std::to_string(version + 1)});
            pg.exec("COMMIT");
        } catch (...) {
            pg.rollback();
            throw;
        }
    }
}

}  // namespace manikind::archive
