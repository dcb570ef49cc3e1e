// The recording database's writers (store/database.hpp): campaigns, cases, trials and their
// states, devices and channels, samples (insert_samples: a re-sent reading is stored once),
// events, notes, results, twin versions and set-ups.
#include "store/database_impl.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <span>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <fmt/core.h>

#include "base/sha256.hpp"

namespace manikind::recorder {

namespace {

std::int64_t utc_now_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

}  // namespace

bool is_terminal_trial_state(std::string_view state) {
    return state == "done" || state == "aborted" || state == "interrupted" || state == "failed";
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

}  // namespace manikind::recorder
