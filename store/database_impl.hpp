#pragma once
// The inside of Database (store/database.hpp), private to the store's four database files:
// database_open.cpp (open, pragmas, migrating), database_schema.cpp (the schema's SQL),
// database_write.cpp (the writers) and database_read.cpp (the readers). The connection
// (Database::Impl), one use of a cached statement (Query) and a write transaction (Transaction).

#include <sqlite3.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <unordered_set>

#include <fmt/core.h>

#include "base/user_error.hpp"
#include "store/database.hpp"

namespace manikind::recorder {

// The schema's steps, oldest first (database_schema.cpp); Database::open applies the missing ones.
extern const std::array<const char*, 9> all_migrations;

namespace {

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

}  // namespace

}  // namespace manikind::recorder
