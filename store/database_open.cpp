// Opening the recording database (store/database.hpp): the file's mode, the journal and
// synchronous pragmas, migrating its schema (database_schema.cpp), opening to read only, and
// the connection's own questions (schema version, journal mode, integrity).
#include "store/database_impl.hpp"

#include <cerrno>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <system_error>
#include <utility>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

namespace manikind::recorder {

namespace {

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

}  // namespace manikind::recorder
