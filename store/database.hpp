#pragma once
// The trial database: one SQLite file per installation holding campaigns, cases, trials,
// devices, channels, samples, events, results and twin versions (docs/recorder.md).
//
// One Database is one sqlite3 connection, used from one thread. Several connections (the
// daemon's and the Recorder's writer thread) may share one file: WAL lets readers run beside
// the one writer, and busy_timeout makes writers queue instead of failing.
//
// Every SQLite failure throws manikind::UserError naming the file and SQLite's message; a
// full disk throws StorageFull, a lock held past the busy timeout StorageBusy, an I/O error
// StorageFault (all UserErrors), which the recorder and the daemon survive.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/user_error.hpp"

struct sqlite3;

namespace manikind::recorder {

// A trial's samples are the rowid range [trial_id << 36, (trial_id + 1) << 36) of `samples`
// (schema version 8): 2^36 rows a trial, 2^27 trials.
constexpr int trial_id_shift = 36;
constexpr std::int64_t trial_id_begin(std::int64_t trial_id) { return trial_id << trial_id_shift; }
constexpr std::int64_t trial_id_end(std::int64_t trial_id) { return (trial_id + 1) << trial_id_shift; }

// A write failed for want of space (SQLITE_FULL, or ENOSPC under any other code). Nothing of the
// failed transaction is stored; everything committed before it still is.
class StorageFull : public UserError {
public:
    explicit StorageFull(const std::string& message) : UserError(message, "disk_full") {}
};

// A write waited out the busy timeout for a lock another connection holds (SQLITE_BUSY or
// SQLITE_LOCKED): a write transaction elsewhere, or in rollback-journal mode a read transaction
// left open. Nothing of the failed transaction is stored; it can be tried again.
class StorageBusy : public UserError {
public:
    explicit StorageBusy(const std::string& message) : UserError(message, "database_locked") {}
};

// The file system failed a read or write (SQLITE_IOERR: an unplugged disk, a dropped network
// share, a medium error). Nothing of the failed transaction is stored; like a full disk it may
// clear (the disk comes back), so the recorder keeps the rows and tries again.
class StorageFault : public UserError {
public:
    explicit StorageFault(const std::string& message) : UserError(message, "storage_error") {}
};

// Sample quality codes stored in samples.quality.
enum class Quality : std::uint8_t { good = 0, stale = 1, out_of_range = 2, comm_error = 3 };

struct SampleRow {
    std::int64_t trial_id = 0;  // 0: outside any trial, stored in the idle log (idle_samples)
    std::int64_t channel_id = 0;
    std::int64_t mono_ns = 0;  // CLOCK_MONOTONIC: orders samples within a trial
    std::int64_t utc_ns = 0;   // wall clock, for people
    double value = 0.0;        // NaN is stored as NULL and read back as NaN
    std::uint8_t quality = 0;  // see Quality
};

struct CampaignRow {
    std::int64_t id = 0;
    std::string name;
    std::string definition_json;
    std::int64_t created_utc_ns = 0;
    std::string state;  // "created" until the daemon says otherwise
};

struct CaseRow {
    std::int64_t id = 0;
    std::int64_t campaign_id = 0;
    std::string name;
    std::string conditions_json;
    std::int64_t position = 0;
};

struct TrialRow {
    std::int64_t id = 0;
    std::int64_t campaign_id = 0;
    std::int64_t case_id = 0;
    std::int64_t replicate = 0;
    std::string state;  // "pending" at creation; terminal: done, aborted, interrupted, failed
    std::string reason;
    std::optional<std::int64_t> started_utc_ns;       // first state change away from "pending"
    std::optional<std::int64_t> ended_utc_ns;         // entry into a terminal state
    std::optional<std::int64_t> steady_from_mono_ns;  // start of the steady-state window
    std::int64_t quality_flags = 0;                   // OR of the flags added so far
    std::string uuid;                                 // 32 hex digits, random, unique (schema version 6)
    std::optional<std::int64_t> setup_id;             // the set-up it ran with (version 7; none before)
};

// What a trial ran with (schema version 7): stored once per distinct content.
struct Setup {
    std::string lab_name;
    std::string chamber;           // [lab] chamber: make, model, serial number
    std::string manikin;           // [lab] manikin
    std::string calibration_json;  // instruments' Type B specs and the register maps (probe scaling)
    std::string config_toml;       // the configuration text the daemon started with
    std::string sha256() const;    // of all five fields: the set-up's name here and in the archive
};

struct SetupRow {
    std::int64_t id = 0;
    std::string sha256;
    std::int64_t first_used_utc_ns = 0;
    Setup setup;
};

struct ChannelRow {
    std::int64_t id = 0;
    std::int64_t device_id = 0;
    std::string device_name;
    std::string name;
    std::string unit;
};

// A lab-notebook entry (docs/recorder.md, "Notes"): append-only.
struct NoteRow {
    std::int64_t id = 0;
    std::int64_t campaign_id = 0;
    std::optional<std::int64_t> trial_id;  // empty: about the campaign as a whole
    std::int64_t utc_ns = 0;
    std::string author;
    std::string kind;                      // comment, operator, ensemble, garment
    std::string text;
};

struct EventRow {
    std::int64_t id = 0;
    std::optional<std::int64_t> trial_id;  // empty: a daemon-wide event
    std::int64_t mono_ns = 0;
    std::int64_t utc_ns = 0;
    std::string severity;  // "info", "warn", "error"
    std::string kind;
    std::string message;
};

struct ResultRow {
    std::int64_t id = 0;
    std::int64_t campaign_id = 0;
    std::int64_t computed_utc_ns = 0;
    std::string json;
};

// True for the states a trial never leaves: done, aborted, interrupted, failed.
bool is_terminal_trial_state(std::string_view state);

// What a committed transaction survives (docs/recorder.md, "Durability"): `process`, a killed
// process (WAL with synchronous = NORMAL: the WAL is synced at checkpoints only); `power`, a
// power cut or kernel crash too (synchronous = FULL: the WAL is synced at every commit).
enum class Durability { process, power };

// How SQLite keeps a transaction atomic (docs/recorder.md, "Journal"): `wal`, a write-ahead
// log that readers never wait for and that never waits for readers, every page written twice
// (log, then checkpoint); `rollback`, the old content of each changed page saved to a
// -journal file first, new pages written once (1.6x the bytes stored at 30-s commits against
// WAL's 2.3x), but a commit waits for running reads and a read for a running commit.
enum class Journal { wal, rollback };

// Opens an SQLite file read-only for a caller that reads it through the C API (archive push),
// as Database::open_read_only does: SQLITE_OPEN_READONLY, and for a WAL-mode file that SQLite
// cannot open so (its -shm cannot be made: read-only media, a folder this user cannot write)
// and that has no -wal file, hence no writer and nothing outside the file, immutable=1. Returns
// SQLite's code; *db is set (and must be closed) either way.
int open_sqlite_read_only(const std::filesystem::path& path, sqlite3** db);

class Database {
public:
    // Opens (creating if absent) and migrates to the latest schema. `journal`: the mode to put
    // the file in; none keeps the file's own (WAL for a new file), so that a reader never
    // switches a lab's database out of the mode its daemon chose. A file another connection
    // holds cannot leave WAL: it stays in WAL, with a warning. Throws UserError if the file is
    // not a database, cannot be put in WAL mode, or has a schema newer than this program.
    static Database open(const std::filesystem::path& path, Durability durability = Durability::process,
                         std::optional<Journal> journal = std::nullopt);
    // For commands that only read (campaigns, log, export, analyze, archive push): opened
    // read-only (SQLite's mode=ro), never created, migrated or switched to another journal, so a
    // mistyped --db cannot turn another program's file into a manikind database. Refuses, with
    // UserError naming the path, what is not a manikind database of this program's schema: a
    // missing or empty file, one that is not SQLite, a database without manikind's tables, one
    // from an older manikind (the daemon upgrades it when it starts on it) or a newer one.
    static Database open_read_only(const std::filesystem::path& path);

    Database(Database&&) noexcept;
    Database& operator=(Database&&) noexcept;
    Database(const Database&) = delete;
    Database& operator=(const Database&) = delete;
    ~Database();

    // Migration i (0-based) takes the schema from version i to i + 1; PRAGMA user_version is
    // the version. Exposed so a test can build an old database.
    static std::span<const char* const> migrations();
    static int latest_schema_version();

    const std::filesystem::path& path() const;
    int schema_version();
    std::string journal_mode();  // "wal", or "truncate" for Journal::rollback
    // How long a statement waits for another connection's lock before StorageBusy (5 s from open).
    void set_busy_timeout(std::chrono::milliseconds timeout);
    int synchronous();  // SQLite's PRAGMA synchronous: 1 NORMAL (Durability::process), 2 FULL (power)
    std::string integrity_check();  // "ok" when fine, else SQLite's findings one per line

    // Campaigns, cases, trials.
    std::int64_t create_campaign(const std::string& name, const std::string& definition_json);  // UserError if the name exists
    std::optional<std::int64_t> find_campaign(const std::string& name);
    void set_campaign_state(std::int64_t campaign_id, const std::string& state);
    std::int64_t add_case(std::int64_t campaign_id, const std::string& name, const std::string& conditions_json,
                          std::int64_t position);
    std::int64_t create_trial(std::int64_t campaign_id, std::int64_t case_id, std::int64_t replicate);
    void set_trial_state(std::int64_t trial_id, const std::string& state, const std::string& reason, std::int64_t utc_ns);
    void set_trial_steady(std::int64_t trial_id, std::int64_t mono_ns);
    void add_trial_flag(std::int64_t trial_id, std::int64_t flag_bits);
    // After a crash: every trial not in a terminal state becomes "interrupted" with reason
    // "daemon restarted" and ended_utc_ns = utc_ns. Returns how many.
    int mark_interrupted_trials(std::int64_t utc_ns);
    // After a crash: campaigns left "created" or "running" become "interrupted" (continuable by
    // starting the same plan again). Returns how many.
    int mark_interrupted_campaigns();

    // Devices and channels: get-or-create. A device's kind and address are updated to the
    // values given; a channel whose unit differs from the stored one is a UserError (its
    // samples so far are in the old unit).
    std::int64_t device_id(const std::string& name, const std::string& kind, const std::string& address);
    std::int64_t channel_id(std::int64_t device_id, const std::string& name, const std::string& unit);
    // The analysts' view trial_table has a column per channel; rebuilt when the channels changed
    // (open calls it, the daemon when a trial ends; a no-op when current).
    void refresh_trial_table();
    // Runs `body` (calls on this Database) as one transaction: all of its writes, or (it threw)
    // none. Nests inside another.
    void atomically(const std::function<void()>& body);

    // Samples in one transaction (the Recorder's writer calls this; other callers may too).
    // A row whose (trial_id, channel_id, mono_ns) is already stored is skipped, keeping the
    // first; returns how many were skipped. A trial or channel id that does not exist fails
    // the whole transaction (foreign keys), so ids must come from create_trial/channel_id.
    // A trial's rows take the ids [trial_id_begin, trial_id_end) in the order they are stored.
    std::size_t insert_samples(std::span<const SampleRow> rows);
    // Removes from `rows` the trial samples already stored (same trial, channel and mono_ns),
    // with one scan per trial instead of insert_samples' lookup per out-of-order row; returns
    // how many. For re-sending a batch that may have been stored (the crash ring).
    std::size_t remove_already_stored(std::vector<SampleRow>& rows);
    // For a connection that only inserts samples (the Recorder's): SQLite's foreign-key checks
    // off for good, since insert_samples checks trial and channel ids itself. Other statements on
    // this connection would go unchecked, so nothing else may use it.
    void check_sample_keys_here();

    std::int64_t add_event(std::optional<std::int64_t> trial_id, std::int64_t mono_ns, std::int64_t utc_ns,
                           const std::string& severity, const std::string& kind, const std::string& message);
    // The lab notebook: appended, never edited (the table's triggers refuse it).
    std::int64_t add_note(const NoteRow& note);
    std::vector<NoteRow> notes(std::int64_t campaign_id);  // by time
    std::int64_t store_result(std::int64_t campaign_id, const std::string& json, std::int64_t utc_ns);
    // Idempotent for the same text; a different text under an existing (name, version) is a UserError.
    std::int64_t store_twin_version(const std::string& name, std::int64_t version, const std::string& toml);
    std::optional<std::string> twin_version_toml(const std::string& name, std::int64_t version);
    std::optional<std::string> latest_twin_version();  // "name vN" of the newest stored, if any
    // Get-or-create by content (its SHA-256); `utc_ns` is kept only when the set-up is new.
    std::int64_t record_setup(const Setup& setup, std::int64_t utc_ns);
    void set_trial_setup(std::int64_t trial_id, std::int64_t setup_id);
    std::optional<SetupRow> setup(std::int64_t setup_id);

    // Queries.
    std::vector<CampaignRow> campaigns();
    std::vector<CaseRow> cases(std::int64_t campaign_id);       // by position
    std::vector<TrialRow> trials(std::int64_t campaign_id);     // by id
    std::optional<TrialRow> trial(std::int64_t trial_id);
    std::vector<ChannelRow> channels();                         // by device name, channel name
    std::vector<SampleRow> samples(std::int64_t trial_id, std::int64_t channel_id);  // by mono_ns
    // Every sample of a trial in time order (mono_ns, then channel_id), one pass over the
    // trial's id range: the way to read many channels.
    void for_each_trial_sample(std::int64_t trial_id, const std::function<void(const SampleRow&)>& visit);
    std::int64_t sample_count(std::int64_t trial_id);
    std::optional<std::int64_t> last_sample_mono_ns(std::int64_t trial_id);  // the latest committed; none before any
    // The idle log (rows pushed with trial_id 0): one channel's readings since a wall time.
    std::vector<SampleRow> idle_samples(std::int64_t channel_id, std::int64_t since_utc_ns);
    std::optional<std::int64_t> newest_idle_utc_ns();  // the idle log's last wall time (a key lookup)
    // The newest wall time recorded anywhere (the newest trial's last sample, the idle log,
    // events), or none in an empty database: a simulated lab's virtual clock starts after it, so
    // a second run never stamps a reading with a time already used.
    std::optional<std::int64_t> newest_utc_ns();
    std::int64_t idle_sample_count();
    // Where the readings stood when a run began (the newest sample id, the idle log's size):
    // what the run stored since is counted from the file itself by rows_since, not from a
    // writer's own tally (issue 60: a tally cannot see rows lost after their commit). The idle
    // log is counted whole, not by stamp: a real clock stepped back stamps new rows below the mark.
    struct RowMark {
        std::int64_t sample_id = -1;
        std::int64_t idle_rows = 0;
    };
    RowMark row_mark();
    std::int64_t rows_since(const RowMark& mark);
    std::vector<EventRow> events(std::optional<std::int64_t> trial_id);  // empty: all events; by mono_ns
    std::optional<ResultRow> latest_result(std::int64_t campaign_id);

    struct Impl;

private:
    explicit Database(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace manikind::recorder
