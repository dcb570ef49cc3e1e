#include "archive/forwarder.hpp"

#include <sqlite3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include <fmt/core.h>

#include "archive/pg.hpp"
#include "archive/pg_schema.hpp"
#include "store/database.hpp"
#include "base/user_error.hpp"

namespace manikind::archive {
namespace {

// The recorder's schema version that gave trials their UUID (store/database_schema.cpp).
constexpr int first_sqlite_version_with_uuid = 6;

// The SQLite side, read-only through the C API: the recorder's Database would migrate (write) on open.
class Source {
public:
    explicit Source(const std::filesystem::path& path) : path_(path) {
        std::error_code ec;
        if (!std::filesystem::is_regular_file(path, ec))
            throw UserError(fmt::format("{}: no such database", path.string()));
        sqlite3* db = nullptr;
        const int rc = recorder::open_sqlite_read_only(path, &db);  // read-only media too
        owner_.reset(db);  // closed on every way out, a throw from this constructor included
        db_ = db;
        if (rc != SQLITE_OK) fail("cannot open");
        // The daemon may be committing: wait for its lock rather than fail.
        sqlite3_busy_timeout(db_, 5000);
        const auto version = single_int("PRAGMA user_version");
        if (!has_table("trials") || !has_table("samples"))
            throw UserError(fmt::format("{}: not a manikind database (no trials or samples table)", path.string()));
        if (version < first_sqlite_version_with_uuid)
            throw UserError(fmt::format("{}: schema version {} has no trial UUIDs (version {}); open it once with this "
                                        "version's manikind or manikin to migrate it, then push",
                                        path.string(), version, first_sqlite_version_with_uuid));
        // One read transaction for the whole push: every table is read from the same snapshot.
        exec("BEGIN");
        single_int("SELECT count(*) FROM sqlite_schema");  // the snapshot starts at the first read
    }
    Source(const Source&) = delete;
    Source& operator=(const Source&) = delete;
    ~Source() { sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr); }

    class Stmt {
    public:
        Stmt(Source& src, const char* sql) : src_(src) {
            if (sqlite3_prepare_v2(src.db_, sql, -1, &s_, nullptr) != SQLITE_OK) src.fail("cannot read");
        }
        Stmt(const Stmt&) = delete;
        Stmt& operator=(const Stmt&) = delete;
        ~Stmt() { sqlite3_finalize(s_); }
        void bind(int i, std::int64_t v) { sqlite3_bind_int64(s_, i, v); }
        void bind(int i, const char* v) { sqlite3_bind_text(s_, i, v, -1, SQLITE_TRANSIENT); }
        void reset() { sqlite3_reset(s_); }
        bool step() {
            const int rc = sqlite3_step(s_);
            if (rc == SQLITE_ROW) return true;
            if (rc != SQLITE_DONE) src_.fail("cannot read");
            return false;
        }
        std::int64_t int64(int c) const { return sqlite3_column_int64(s_, c); }
        bool is_null(int c) const { return sqlite3_column_type(s_, c) == SQLITE_NULL; }
        double real(int c) const { return sqlite3_column_double(s_, c); }
        std::string text(int c) const {
            const auto* p = sqlite3_column_text(s_, c);
            return p ? std::string(reinterpret_cast<const char*>(p), static_cast<std::size_t>(sqlite3_column_bytes(s_, c)))
                     : std::string();
        }

    private:
        Source& src_;
        sqlite3_stmt* s_ = nullptr;
    };

    [[noreturn]] void fail(const char* what) const {
        throw UserError(fmt::format("{}: {}: {}", path_.string(), what, db_ ? sqlite3_errmsg(db_) : "out of memory"));
    }
    bool has_table(const char* name) {
        Stmt s(*this, "SELECT 1 FROM sqlite_schema WHERE type = 'table' AND name = ?1");
        s.bind(1, name);
        return s.step();
    }

private:
    void exec(const char* sql) {
        if (sqlite3_exec(db_, sql, nullptr, nullptr, nullptr) != SQLITE_OK) fail("cannot read");
    }
    std::int64_t single_int(const char* sql) {
        Stmt s(*this, sql);
        return s.step() ? s.int64(0) : 0;
    }

    struct Close {
        void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
    };
    std::filesystem::path path_;
    std::unique_ptr<sqlite3, Close> owner_;
    sqlite3* db_ = nullptr;
};

void check_lab_id(const std::string& lab_id) {
    const bool ok_length = !lab_id.empty() && lab_id.size() <= 64;
    bool ok_chars = true;
    for (const char c : lab_id)
        ok_chars = ok_chars && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                                c == '-' || c == '_' || c == '.');
    if (!ok_length || !ok_chars)
        throw UserError(fmt::format("lab id '{}': expected 1 to 64 letters, digits, '-', '_' or '.'", lab_id));
}

std::int64_t now_utc_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

std::string opt_text(const std::optional<std::int64_t>& v) { return v ? std::to_string(*v) : std::string(); }

// A double in COPY's text format: the shortest text that reads back to the same bits.
void append_copy_double(std::string& out, const Source::Stmt& s, int column) {
    if (s.is_null(column)) {
        out += "\\N";
        return;
    }
    const double v = s.real(column);
    if (std::isnan(v)) out += "\\N";  // the recorder's convention: NaN is stored as NULL
    else if (std::isinf(v)) out += v > 0 ? "Infinity" : "-Infinity";
    else out += fmt::format("{}", v);
}

struct SampleProgress {
    std::optional<std::int64_t> last_mono_ns, last_channel_id;
    std::int64_t rows_sent = 0;
    bool terminal_pass = false;
    bool complete = false;
};

class Pusher {
public:
    Pusher(Source& src, PgConnection& pg, std::string lab_id, const PushOptions& options)
        : src_(src), pg_(pg), lab_(std::move(lab_id)), options_(options) {}

    PushResult run() {
        result_.archive = pg_.describe();
        result_.lab_id = lab_;
        result_.archive_schema_version = migrate_archive(pg_);
        take_lab_lock();
        in_transaction([&] { send_metadata(); });
        in_transaction([&] { send_events(); });
        in_transaction([&] { send_notes(); });
        send_samples();
        send_idle_samples();
        return result_;
    }

private:
    template <typename F>
    void in_transaction(F&& body) {
        pg_.exec("BEGIN");
        try {
            body();
            pg_.exec("COMMIT");
        } catch (...) {
            pg_.rollback();
            throw;
        }
    }

    // Two pushes of one lab at once would only repeat each other's rows (harmless), but their
    // progress rows would race; the second is refused instead. Released when the session ends,
    // which the server sees a moment after the client has gone: a push that follows another at
    // once (the daemon's next pass) would find it still held, so it is retried for up to 10 s.
    void take_lab_lock() {
        const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        for (;;) {
            if (pg_.exec("SELECT pg_try_advisory_lock(hashtextextended($1, 7419002))", {lab_}).text(0, 0) == "t") return;
            if (std::chrono::steady_clock::now() >= give_up)
                throw UserError(fmt::format("archive {}: another push for lab '{}' is running", result_.archive, lab_),
                                "archive_refused", ExitStatus::refused);
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
    }

    // Campaigns, trials (each with its case's name and conditions) and channels: few rows, upserted
    // one by one. `added` counts rows inserted or whose values changed (a trial that ended since).
    void send_metadata() {
        pg_.exec("INSERT INTO labs (lab_id, name, first_push_utc_ns) VALUES ($1, $2, $3) ON CONFLICT DO NOTHING",
                 {lab_, options_.lab_name.empty() ? lab_ : options_.lab_name, std::to_string(now_utc_ns())});

        Source::Stmt campaigns(src_, "SELECT name, definition_json, created_utc_ns, state FROM campaigns ORDER BY id");
        while (campaigns.step()) {
            auto r = pg_.exec(
                "INSERT INTO campaigns AS c (lab_id, campaign_name, definition_json, created_utc_ns, state)"
                " VALUES ($1, $2, $3, $4, $5) ON CONFLICT (lab_id, campaign_name) DO UPDATE"
                " SET definition_json = EXCLUDED.definition_json, created_utc_ns = EXCLUDED.created_utc_ns,"
                " state = EXCLUDED.state WHERE (c.definition_json, c.created_utc_ns, c.state)"
                " IS DISTINCT FROM (EXCLUDED.definition_json, EXCLUDED.created_utc_ns, EXCLUDED.state)",
                {lab_, campaigns.text(0), campaigns.text(1), std::to_string(campaigns.int64(2)), campaigns.text(3)});
            count(result_.campaigns, r.affected());
        }

        // Set-ups before the trials that name them. A file from before version 7 has none.
        const bool has_setups = src_.has_table("setups");
        if (has_setups) {
            Source::Stmt setups(src_, "SELECT sha256, lab_name, chamber, manikin, calibration_json, config_toml,"
                                      " first_used_utc_ns FROM setups ORDER BY id");
            while (setups.step()) {
                auto r = pg_.exec("INSERT INTO setups (lab_id, setup_sha256, lab_name, chamber, manikin,"
                                  " calibration_json, config_toml, first_used_utc_ns)"
                                  " VALUES ($1, $2, $3, $4, $5, $6, $7, $8) ON CONFLICT DO NOTHING",
                                  {lab_, setups.text(0), setups.text(1), setups.text(2), setups.text(3), setups.text(4),
                                   setups.text(5), std::to_string(setups.int64(6))});
                count(result_.setups, r.affected());
            }
        }
        const std::string trials_sql = fmt::format(
            "SELECT t.id, t.uuid, c.name, k.name, t.replicate, t.state, t.reason, t.started_utc_ns, t.ended_utc_ns,"
            " k.conditions_json, {} FROM trials t JOIN campaigns c ON c.id = t.campaign_id"
            " JOIN cases k ON k.id = t.case_id {} ORDER BY t.id",
            has_setups ? "s.sha256" : "NULL", has_setups ? "LEFT JOIN setups s ON s.id = t.setup_id" : "");
        Source::Stmt trials(src_, trials_sql.c_str());
        while (trials.step()) {
            TrialInfo info{trials.int64(0), trials.text(1), recorder::is_terminal_trial_state(trials.text(5)), {}};
            std::optional<std::int64_t> started, ended;
            if (!trials.is_null(7)) started = trials.int64(7);
            if (!trials.is_null(8)) ended = trials.int64(8);
            // A trial UUID pushed by another lab stays that lab's: the update is skipped and
            // caught by the ownership check below.
            const bool no_setup = trials.is_null(10);
            auto r = pg_.exec_nullable(
                "INSERT INTO trials AS t (trial_uuid, lab_id, campaign_name, case_name, replicate, state, reason,"
                " started_utc_ns, ended_utc_ns, conditions_json, setup_sha256)"
                " VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)"
                " ON CONFLICT (trial_uuid) DO UPDATE SET campaign_name = EXCLUDED.campaign_name,"
                " case_name = EXCLUDED.case_name, replicate = EXCLUDED.replicate, state = EXCLUDED.state,"
                " reason = EXCLUDED.reason, started_utc_ns = EXCLUDED.started_utc_ns,"
                " ended_utc_ns = EXCLUDED.ended_utc_ns, conditions_json = EXCLUDED.conditions_json,"
                " setup_sha256 = EXCLUDED.setup_sha256"
                " WHERE t.lab_id = EXCLUDED.lab_id AND (t.campaign_name, t.case_name, t.replicate, t.state, t.reason,"
                " t.started_utc_ns, t.ended_utc_ns, t.conditions_json, t.setup_sha256) IS DISTINCT FROM"
                " (EXCLUDED.campaign_name, EXCLUDED.case_name, EXCLUDED.replicate, EXCLUDED.state, EXCLUDED.reason,"
                " EXCLUDED.started_utc_ns, EXCLUDED.ended_utc_ns, EXCLUDED.conditions_json, EXCLUDED.setup_sha256)",
                {info.uuid, lab_, trials.text(2), trials.text(3), std::to_string(trials.int64(4)), trials.text(5),
                 trials.text(6), opt_text(started), opt_text(ended), trials.text(9), no_setup ? "" : trials.text(10)},
                {false, false, false, false, false, false, false, !started, !ended, false, no_setup});
            count(result_.trials, r.affected());
            auto owner = pg_.exec("SELECT lab_id, trial_key FROM trials WHERE trial_uuid = $1", {info.uuid});
            info.key = std::to_string(owner.int64(0, 1));
            if (owner.text(0, 0) != lab_)
                throw UserError(fmt::format("archive {}: trial {} belongs to lab '{}' there, not '{}': was this "
                                            "database pushed under another lab id?",
                                            result_.archive, info.uuid, owner.text(0, 0), lab_),
                                "archive_refused", ExitStatus::refused);
            trials_.push_back(std::move(info));
        }

        Source::Stmt channels(src_, "SELECT ch.id, d.name, ch.name, ch.unit FROM channels ch"
                                    " JOIN devices d ON d.id = ch.device_id ORDER BY ch.id");
        while (channels.step()) {
            std::string device = channels.text(1), channel = channels.text(2);
            auto r = pg_.exec("INSERT INTO channels AS c (lab_id, device, channel, unit) VALUES ($1, $2, $3, $4)"
                              " ON CONFLICT (lab_id, device, channel) DO UPDATE SET unit = EXCLUDED.unit"
                              " WHERE c.unit IS DISTINCT FROM EXCLUDED.unit",
                              {lab_, device, channel, channels.text(3)});
            count(result_.channels, r.affected());
            // Idle samples carry the names, pre-escaped for COPY; trial samples the archive's key.
            std::string names;
            append_copy_text(names, device);
            names += '\t';
            append_copy_text(names, channel);
            names += '\t';
            channel_names_.emplace(channels.int64(0), std::move(names));
            auto key = pg_.exec("SELECT channel_key FROM channels WHERE lab_id = $1 AND device = $2 AND channel = $3",
                                {lab_, device, channel});
            channel_keys_.emplace(channels.int64(0), std::to_string(key.int64(0, 0)) + '\t');
        }

        // The SQLite column is the device's address (host:port, serial port, CAN interface).
        Source::Stmt devices(src_, "SELECT name, kind, address FROM devices ORDER BY id");
        while (devices.step()) {
            auto r = pg_.exec("INSERT INTO devices AS d (lab_id, device, kind, transport) VALUES ($1, $2, $3, $4)"
                              " ON CONFLICT (lab_id, device) DO UPDATE SET kind = EXCLUDED.kind,"
                              " transport = EXCLUDED.transport WHERE (d.kind, d.transport)"
                              " IS DISTINCT FROM (EXCLUDED.kind, EXCLUDED.transport)",
                              {lab_, devices.text(0), devices.text(1), devices.text(2)});
            count(result_.devices, r.affected());
        }

        // A stored result is never changed in SQLite (a new analysis is a new row): insert only.
        Source::Stmt results(src_, "SELECT c.name, r.computed_utc_ns, r.json FROM results r"
                                   " JOIN campaigns c ON c.id = r.campaign_id ORDER BY r.id");
        while (results.step()) {
            auto r = pg_.exec("INSERT INTO results (lab_id, campaign_name, computed_utc_ns, json)"
                              " VALUES ($1, $2, $3, $4) ON CONFLICT DO NOTHING",
                              {lab_, results.text(0), std::to_string(results.int64(1)), results.text(2)});
            count(result_.results, r.affected());
        }

        // The recorder refuses new text under a stored (name, version); the update covers a
        // file replaced by another that reuses the pair.
        Source::Stmt twins(src_, "SELECT name, version, toml, created_utc_ns FROM twin_versions ORDER BY id");
        while (twins.step()) {
            auto r = pg_.exec("INSERT INTO twin_versions AS t (lab_id, twin_name, version, toml, created_utc_ns)"
                              " VALUES ($1, $2, $3, $4, $5) ON CONFLICT (lab_id, twin_name, version) DO UPDATE"
                              " SET toml = EXCLUDED.toml, created_utc_ns = EXCLUDED.created_utc_ns"
                              " WHERE (t.toml, t.created_utc_ns) IS DISTINCT FROM (EXCLUDED.toml,"
                              " EXCLUDED.created_utc_ns)",
                              {lab_, twins.text(0), std::to_string(twins.int64(1)), twins.text(2),
                               std::to_string(twins.int64(3))});
            count(result_.twin_versions, r.affected());
        }
    }

    // Events are few (stages, alarms, faults) and have no key beyond their content: all of them
    // go every push, through a staging table, and the unique index drops the ones already there.
    void send_events() {
        pg_.exec("CREATE TEMP TABLE IF NOT EXISTS event_staging (trial_uuid text, mono_ns bigint, utc_ns bigint,"
                 " severity text, kind text, message text) ON COMMIT DELETE ROWS");
        Source::Stmt events(src_, "SELECT t.uuid, e.mono_ns, e.utc_ns, e.severity, e.kind, e.message FROM events e"
                                  " LEFT JOIN trials t ON t.id = e.trial_id ORDER BY e.id");
        std::string data;
        std::int64_t n = 0;
        while (events.step()) {
            if (events.is_null(0)) data += "\\N";
            else append_copy_text(data, events.text(0));
            data += fmt::format("\t{}\t{}\t", events.int64(1), events.int64(2));
            append_copy_text(data, events.text(3));
            data += '\t';
            append_copy_text(data, events.text(4));
            data += '\t';
            append_copy_text(data, events.text(5));
            data += '\n';
            ++n;
        }
        if (n == 0) return;
        pg_.copy_in("COPY event_staging FROM STDIN", data);
        auto r = pg_.exec("INSERT INTO events (lab_id, trial_uuid, mono_ns, utc_ns, severity, kind, message)"
                          " SELECT $1, trial_uuid, mono_ns, utc_ns, severity, kind, message FROM event_staging"
                          " ON CONFLICT DO NOTHING",
                          {lab_});
        result_.events.sent += n;
        result_.events.added += r.affected();
    }

    // The lab notebook: few rows, all sent every push like events; the unique index keeps one of each.
    void send_notes() {
        if (!src_.has_table("notes")) return;  // a recording from before the notebook (schema < 9)
        Source::Stmt notes(src_, "SELECT c.name, t.uuid, n.utc_ns, n.author, n.kind, n.text FROM notes n"
                                 " JOIN campaigns c ON c.id = n.campaign_id LEFT JOIN trials t ON t.id = n.trial_id ORDER BY n.id");
        while (notes.step()) {
            const bool no_trial = notes.is_null(1);
            auto r = pg_.exec_nullable("INSERT INTO notes (lab_id, campaign_name, trial_uuid, utc_ns, author, kind, text)"
                                       " VALUES ($1, $2, $3, $4, $5, $6, $7) ON CONFLICT DO NOTHING",
                                       {lab_, notes.text(0), no_trial ? std::string() : notes.text(1), std::to_string(notes.int64(2)),
                                        notes.text(3), notes.text(4), notes.text(5)},
                                       {false, false, no_trial, false, false, false, false});
            ++result_.notes.sent;
            result_.notes.added += r.affected();
        }
    }

    SampleProgress load_progress(const std::string& uuid) {
        auto r = pg_.exec("SELECT last_mono_ns, last_channel_id, rows_sent, terminal_pass, complete FROM forward_progress"
                          " WHERE lab_id = $1 AND source_table = 'samples' AND scope = $2",
                          {lab_, uuid});
        SampleProgress p;
        if (r.rows() == 0) return p;
        if (!r.is_null(0, 0)) p.last_mono_ns = r.int64(0, 0);
        if (!r.is_null(0, 1)) p.last_channel_id = r.int64(0, 1);
        p.rows_sent = r.int64(0, 2);
        p.terminal_pass = r.text(0, 3) == "t";
        p.complete = r.text(0, 4) == "t";
        return p;
    }

    void save_progress(const std::string& uuid, const SampleProgress& p) {
        pg_.exec_nullable(
            "INSERT INTO forward_progress (lab_id, source_table, scope, last_mono_ns, last_channel_id, rows_sent,"
            " terminal_pass, complete, updated_utc_ns) VALUES ($1, 'samples', $2, $3, $4, $5, $6, $7, $8)"
            " ON CONFLICT (lab_id, source_table, scope) DO UPDATE SET last_mono_ns = EXCLUDED.last_mono_ns,"
            " last_channel_id = EXCLUDED.last_channel_id, rows_sent = EXCLUDED.rows_sent,"
            " terminal_pass = EXCLUDED.terminal_pass, complete = EXCLUDED.complete,"
            " updated_utc_ns = EXCLUDED.updated_utc_ns",
            {lab_, uuid, opt_text(p.last_mono_ns), opt_text(p.last_channel_id), std::to_string(p.rows_sent),
             p.terminal_pass ? "true" : "false", p.complete ? "true" : "false", std::to_string(now_utc_ns())},
            {false, false, !p.last_mono_ns, !p.last_channel_id, false, false, false, false});
    }

    // Each trial from where its progress row says, in chunks of options_.chunk_rows in key order
    // (mono_ns, channel id), each chunk committed with the progress that covers it.
    //
    // A running trial is sent up to the snapshot. Its rows need not commit in key order (each
    // device's batch commits on its own), so a row committed later may sort before the progress
    // key: the first push after the trial ends therefore sends it again from the start (a
    // "terminal pass"), and only that pass marks it complete.
    //
    // Rows past the saved progress key were never committed to the archive (the key commits with
    // its rows), so they go straight in with COPY; only the chunks of a terminal pass that reach
    // back to what an earlier pass sent go through a staging table and ON CONFLICT DO NOTHING.
    // Were the progress row lost while its rows stayed, the plain COPY would meet a key already
    // there: that chunk is sent again the careful way (counted in result_.chunks_resent).
    void send_samples() {
        pg_.exec("CREATE TEMP TABLE IF NOT EXISTS sample_staging (trial_key integer, mono_ns bigint, channel_key integer,"
                 " utc_ns bigint, value double precision, quality smallint) ON COMMIT DELETE ROWS");
        Source::Stmt read(src_, "SELECT mono_ns, channel_id, utc_ns, value, quality FROM samples"
                                " WHERE id >= (?1 << 36) AND id < ((?1 + 1) << 36) AND (mono_ns, channel_id) > (?2, ?3)"
                                " ORDER BY mono_ns, channel_id LIMIT ?4");
        const auto chunk_rows = static_cast<std::int64_t>(std::max<std::size_t>(options_.chunk_rows, 1));
        for (const auto& trial : trials_) {
            auto progress = load_progress(trial.uuid);
            if (progress.complete) {
                ++result_.trials_complete;
                continue;
            }
            // Up to this key (mono_ns, channel id) rows may already be in the archive.
            std::optional<std::pair<std::int64_t, std::int64_t>> sent_up_to;
            if (progress.last_mono_ns && progress.last_channel_id)
                sent_up_to = std::pair{*progress.last_mono_ns, *progress.last_channel_id};
            if (trial.terminal && !progress.terminal_pass) {
                progress = SampleProgress{};
                progress.terminal_pass = true;
            } else {
                sent_up_to.reset();  // resuming past the key: nothing ahead of it was committed
            }
            const std::string row_start = trial.key + '\t';
            for (;;) {
                read.reset();
                read.bind(1, trial.id);
                read.bind(2, progress.last_mono_ns.value_or(std::numeric_limits<std::int64_t>::min()));
                read.bind(3, progress.last_channel_id.value_or(std::numeric_limits<std::int64_t>::min()));
                read.bind(4, chunk_rows);
                std::string data;
                std::int64_t n = 0;
                std::optional<std::pair<std::int64_t, std::int64_t>> first_key;
                while (read.step()) {
                    const auto channel = read.int64(1);
                    const auto key = channel_keys_.find(channel);
                    if (key == channel_keys_.end()) src_.fail("a sample names a channel that does not exist");
                    progress.last_mono_ns = read.int64(0);
                    progress.last_channel_id = channel;
                    if (!first_key) first_key = std::pair{read.int64(0), channel};
                    data += row_start;
                    data += fmt::format("{}\t", read.int64(0));
                    data += key->second;
                    data += fmt::format("{}\t", read.int64(2));
                    append_copy_double(data, read, 3);
                    data += fmt::format("\t{}\n", read.int64(4));
                    ++n;
                }
                const bool last_chunk = n < chunk_rows;
                if (n == 0 && !trial.terminal) break;  // a running trial with nothing new: no progress to record
                progress.rows_sent += n;
                progress.complete = trial.terminal && last_chunk;
                // A re-send: this chunk starts at or before what an earlier pass committed.
                const bool resend = sent_up_to && first_key && *first_key <= *sent_up_to;
                std::int64_t added = 0;
                const auto send = [&](bool careful) {
                    in_transaction([&] {
                        if (n > 0) {
                            // The trial, checked once per chunk (sample_rows has no foreign key).
                            if (pg_.exec("SELECT 1 FROM trials WHERE trial_key = $1 FOR KEY SHARE", {trial.key}).rows() != 1)
                                throw UserError(fmt::format("archive {}: trial {} vanished during the push", result_.archive, trial.uuid),
                                                "archive_refused", ExitStatus::refused);
                            if (careful) {
                                pg_.copy_in("COPY sample_staging FROM STDIN", data);
                                added = pg_.exec("INSERT INTO sample_rows SELECT * FROM sample_staging ON CONFLICT DO NOTHING").affected();
                            } else {
                                pg_.copy_in("COPY sample_rows (trial_key, mono_ns, channel_key, utc_ns, value, quality) FROM STDIN", data);
                                added = n;
                            }
                        }
                        save_progress(trial.uuid, progress);
                    });
                };
                if (resend) {
                    send(true);
                } else {
                    try {
                        send(false);
                    } catch (const UserError& e) {
                        if (e.code() != "archive_refused") throw;  // the server gone: resumed by the next push
                        send(true);  // a key already there though no progress said so
                        ++result_.chunks_resent;
                    }
                }
                if (n > 0) {
                    ++result_.chunks;
                    result_.samples.sent += n;
                    result_.samples.added += added;
                    if (options_.after_chunk) options_.after_chunk(ChunkCommitted{trial.uuid, n, added});
                }
                if (last_chunk) break;
            }
            if (trial.terminal) ++result_.trials_complete;
            else ++result_.trials_partial;
        }
    }

    // The idle log, in chunks in the SQLite key order (utc_ns, channel id), each committed with
    // the progress row (source_table 'idle_samples', scope ''), as send_samples.
    //
    // The log is appended in wall-clock order, but not exactly: devices stamp their readings
    // themselves and the recorder commits in batches, so a row may commit after one a little
    // newer; and a clock stepped back (NTP, set by hand) writes rows far behind what was sent.
    // Hence (docs/archive.md): rows of the last idle_settle_ns before the snapshot's newest are
    // sent every push but the progress key stops short of them, so a late row there is still
    // sent; and rows_sent always equals the number of SQLite rows up to the progress key (the
    // chunks are exactly those rows), so a count that differs means rows appeared behind the key
    // (or were removed): the log is then sent again from the start, rows already there skipped.
    // The count is one scan of the key range, the price of not losing those rows; the daemon's
    // forwarder makes it hourly (PushOptions::check_idle_log), so such rows may wait up to an hour.
    static constexpr std::int64_t idle_settle_ns = 60'000'000'000;

    void send_idle_samples() {
        pg_.exec("CREATE TEMP TABLE IF NOT EXISTS idle_staging (device text, channel text, utc_ns bigint,"
                 " value double precision, quality smallint) ON COMMIT DELETE ROWS");
        // A key before every row stands for "none" (plain values: GCC's maybe-uninitialized
        // misfires on an optional of this struct).
        struct Key {
            std::int64_t utc_ns = std::numeric_limits<std::int64_t>::min();
            std::int64_t channel_id = std::numeric_limits<std::int64_t>::min();
        };
        Key progress;               // last settled row committed
        bool has_progress = false;
        std::int64_t rows_sent = 0;  // SQLite rows up to `progress`
        {
            auto r = pg_.exec("SELECT last_utc_ns, last_channel_id, rows_sent FROM forward_progress"
                              " WHERE lab_id = $1 AND source_table = 'idle_samples' AND scope = ''",
                              {lab_});
            if (r.rows() > 0 && !r.is_null(0, 0) && !r.is_null(0, 1)) {
                progress = Key{r.int64(0, 0), r.int64(0, 1)};
                has_progress = true;
                rows_sent = r.int64(0, 2);
            }
        }
        if (has_progress && options_.check_idle_log) {
            Source::Stmt behind(src_, "SELECT count(*) FROM idle_samples WHERE (utc_ns, channel_id) <= (?1, ?2)");
            behind.bind(1, progress.utc_ns);
            behind.bind(2, progress.channel_id);
            if (behind.step() && behind.int64(0) != rows_sent) {
                result_.idle_resent = true;
                progress = Key{};
                has_progress = false;
                rows_sent = 0;
            }
        }
        std::int64_t settled_utc_ns = std::numeric_limits<std::int64_t>::min();
        {
            Source::Stmt newest(src_, "SELECT max(utc_ns) FROM idle_samples");
            if (newest.step() && !newest.is_null(0)) settled_utc_ns = newest.int64(0) - idle_settle_ns;
        }
        Source::Stmt read(src_, "SELECT utc_ns, channel_id, value, quality FROM idle_samples"
                                " WHERE (utc_ns, channel_id) > (?1, ?2) ORDER BY utc_ns, channel_id LIMIT ?3");
        const auto chunk_rows = static_cast<std::int64_t>(std::max<std::size_t>(options_.chunk_rows, 1));
        Key cursor = progress;  // last row read, settled or not
        for (;;) {
            read.reset();
            read.bind(1, cursor.utc_ns);
            read.bind(2, cursor.channel_id);
            read.bind(3, chunk_rows);
            std::string data;
            std::int64_t n = 0;
            while (read.step()) {
                const Key key{read.int64(0), read.int64(1)};
                const auto names = channel_names_.find(key.channel_id);
                if (names == channel_names_.end()) src_.fail("an idle sample names a channel that does not exist");
                cursor = key;
                if (key.utc_ns <= settled_utc_ns) {
                    progress = key;
                    has_progress = true;
                    ++rows_sent;
                }
                data += names->second;
                data += fmt::format("{}\t", key.utc_ns);
                append_copy_double(data, read, 2);
                data += fmt::format("\t{}\n", read.int64(3));
                ++n;
            }
            if (n == 0) break;
            std::int64_t added = 0;
            in_transaction([&] {
                pg_.copy_in("COPY idle_staging FROM STDIN", data);
                added = pg_.exec("INSERT INTO idle_samples (lab_id, device, channel, utc_ns, value, quality)"
                                 " SELECT $1, device, channel, utc_ns, value, quality FROM idle_staging"
                                 " ON CONFLICT DO NOTHING",
                                 {lab_})
                            .affected();
                pg_.exec_nullable(
                    "INSERT INTO forward_progress (lab_id, source_table, scope, last_utc_ns, last_channel_id,"
                    " rows_sent, updated_utc_ns) VALUES ($1, 'idle_samples', '', $2, $3, $4, $5)"
                    " ON CONFLICT (lab_id, source_table, scope) DO UPDATE SET last_utc_ns = EXCLUDED.last_utc_ns,"
                    " last_channel_id = EXCLUDED.last_channel_id, rows_sent = EXCLUDED.rows_sent,"
                    " updated_utc_ns = EXCLUDED.updated_utc_ns",
                    {lab_, std::to_string(progress.utc_ns), std::to_string(progress.channel_id),
                     std::to_string(rows_sent), std::to_string(now_utc_ns())},
                    {false, !has_progress, !has_progress, false, false});
            });
            ++result_.idle_chunks;
            result_.idle_samples.sent += n;
            result_.idle_samples.added += added;
            if (n < chunk_rows) break;
        }
    }

    static void count(TableCounts& c, std::int64_t added) {
        ++c.sent;
        c.added += added;
    }

    struct TrialInfo {
        std::int64_t id;
        std::string uuid;
        bool terminal;
        std::string key;  // the archive's trial_key, as text
    };

    Source& src_;
    PgConnection& pg_;
    std::string lab_;
    const PushOptions& options_;
    PushResult result_;
    std::vector<TrialInfo> trials_;
    std::unordered_map<std::int64_t, std::string> channel_names_;  // id -> "device\tchannel\t", COPY-escaped
    std::unordered_map<std::int64_t, std::string> channel_keys_;   // id -> "<archive channel_key>\t"
};

}  // namespace

PushResult push(const std::filesystem::path& sqlite_path, const std::string& conninfo, const std::string& lab_id,
                const PushOptions& options) {
    check_lab_id(lab_id);
    PgConnection::check_conninfo(conninfo);
    Source src(sqlite_path);
    auto pg = PgConnection::connect(conninfo);
    return Pusher(src, pg, lab_id, options).run();
}

}  // namespace manikind::archive
