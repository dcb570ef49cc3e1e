#pragma once
// The recording's one writer: acquisition threads push() rows, a writer thread with its own
// SQLite connection commits them in batches. push() never waits for the disk; when the queue
// is full the row is dropped and counted, so a stalled disk shows up as a number, not as a
// late sample on the manikin's control loop.
//
// Every other write (events, trial and campaign states, results, devices) goes through the same
// thread and connection: post() for those the caller need not wait for, call() for those whose
// answer it needs (an id). One writer means no lock contention inside the daemon; a lock held by
// another program, a full disk or an I/O error makes every write wait, in order, counted, and
// never lost or fatal (issue 30).
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <exception>
#include <filesystem>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <type_traits>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "store/crash_ring.hpp"
#include "store/database.hpp"

namespace manikind::recorder {

struct RecorderOptions {
    std::size_t queue_capacity = 1 << 16;  // rows waiting to be taken by the writer
    std::size_t max_batch_rows = 4096;     // rows per transaction
    // A row waits at most this long (plus one commit) before its transaction starts: what a
    // power cut can lose, and what a killed process can lose when there is no crash ring. Each
    // commit rewrites at least the page it appends to, so shorter means more bytes written per
    // row ([recorder] commit_interval_s; docs/recorder.md, "Write amplification"). The
    // daemon's default is 30 s; this class's stays 1 s for callers without a ring.
    std::chrono::milliseconds max_batch_delay{1000};
    int max_commit_attempts = 5;  // then the batch is discarded (counted in lost) and logged
    // A full disk is not counted against max_commit_attempts: the rows wait in memory (new ones
    // are dropped once the queue is full) and the commit is tried again this often, and at each
    // flush(), until space returns. At shutdown the usual attempts apply, then the rows are lost.
    std::chrono::milliseconds full_disk_retry{1000};
    // A lock held by another connection (StorageBusy: a write transaction elsewhere, or with
    // journal = rollback a read transaction left open) is treated like a full disk: the rows wait
    // in memory, not counted against max_commit_attempts, and each commit waits this long for it.
    std::chrono::milliseconds lock_timeout{5000};
    Durability durability = Durability::process;  // [recorder] durability
    // [recorder] journal: the mode the Recorder puts the file in; none keeps the file's own.
    std::optional<Journal> journal;
    // Where the crash ring lives (crash_ring.hpp): a copy of every sample not yet committed, in
    // shared memory, stored by the next Recorder if this process dies. Empty: no ring, and a
    // crash loses what is not committed ([recorder] crash_ring_dir).
    std::filesystem::path crash_ring_dir = "/dev/shm";
    // Writes other than samples waiting for the writer (post()); past this one is refused and
    // counted in jobs_lost. An hour of 1-Hz events held up by a lock is 3600.
    std::size_t max_jobs = 100000;
};

struct RecorderStats {
    std::uint64_t accepted = 0;        // push() returned true
    std::uint64_t committed = 0;       // stored by a committed transaction
    std::uint64_t duplicates = 0;      // skipped: (trial, channel, mono_ns) was already stored
    std::uint64_t dropped = 0;         // push() returned false: queue full
    std::uint64_t batches = 0;         // committed transactions
    std::uint64_t failed_commits = 0;  // transactions that failed (then retried)
    std::uint64_t lost = 0;            // accepted but discarded after max_commit_attempts failures
    double max_commit_ms = 0.0;        // longest successful transaction, BEGIN to COMMIT
    std::size_t queue_depth = 0;       // accepted, not yet committed or lost
    bool storage_full = false;         // the latest commit failed for want of space
    std::string storage_error;         // its message (file, what, SQLite's words)
    std::uint64_t full_disk_commits = 0;  // commits that failed for want of space
    bool locked = false;               // the latest commit found the database locked by another connection
    std::uint64_t locked_commits = 0;  // commits that failed so
    bool io_error = false;             // the latest commit failed with an I/O error (SQLITE_IOERR)
    std::uint64_t io_error_commits = 0;
    std::uint64_t jobs_done = 0;       // post()ed and call()ed writes made
    std::uint64_t jobs_failed = 0;     // post()ed writes that failed for another reason (logged: a bug, not storage)
    std::uint64_t jobs_lost = 0;       // post() refused (max_jobs waiting), or given up at shutdown
    std::size_t jobs_waiting = 0;      // post()ed, not yet made
    std::uint64_t recovered = 0;       // samples a crashed predecessor left in the crash ring, stored at start
    std::string crash_ring;            // the ring's file; empty when running without one
    std::string journal;               // SQLite's journal mode on the file: "wal" or "truncate" (rollback)
};

class Recorder {
public:
    // Opens the database (its own connection, in the writer thread) before returning; throws
    // UserError as Database::open does.
    explicit Recorder(std::filesystem::path db_path, RecorderOptions options = {});
    // Commits everything accepted, then joins the writer.
    ~Recorder();
    Recorder(const Recorder&) = delete;
    Recorder& operator=(const Recorder&) = delete;

    // Never waits for the writer: a short critical section and no allocation. False (and
    // dropped + 1) when the queue is full.
    bool push(const SampleRow& row) noexcept;
    // The same, for a caller that keeps a refused row and offers it again (the daemon's
    // overflow): a refusal is not counted as dropped.
    bool offer(const SampleRow& row) noexcept;
    // offer() for rows in order under one lock (a virtual-clock step's readings): takes the
    // longest prefix that fits and returns its length; the caller keeps the rest, in order.
    std::size_t offer_many(std::span<const SampleRow> rows) noexcept;
    using Job = std::function<void(Database&)>;
    // A write made by the writer thread on its connection, after the rows it has in hand, in the
    // order posted. A lock held elsewhere, a full disk or an I/O error: it waits at the head of
    // the line and is tried again (counted in the stats), never dropped while the program runs.
    // Any other failure is logged and counted in jobs_failed. False when max_jobs already wait.
    bool post(Job job);
    // Runs `fn` on the writer thread and returns its result, or throws what it threw. While the
    // writer waits on a lock, a full disk or an I/O error, it throws StorageBusy / StorageFull /
    // StorageFault at once rather than queueing: a caller that needs an answer (an id) tries
    // again later instead of being held for as long as the lock lasts.
    template <class F>
    std::invoke_result_t<F, Database&> call(F&& fn) {
        using R = std::invoke_result_t<F, Database&>;
        if constexpr (std::is_void_v<R>) {
            run_call([&](Database& db) { fn(db); });
        } else {
            std::optional<R> result;
            run_call([&](Database& db) { result.emplace(fn(db)); });
            return std::move(*result);
        }
    }
    // Returns true when every row accepted and every write posted before the call is made (or
    // lost after retries); false, after one more attempt, while the disk is full, the database
    // locked elsewhere or the file system failing (they stay queued).
    bool flush();
    RecorderStats stats() const;

private:
    struct PendingJob {
        Job run;
        std::shared_ptr<std::promise<void>> reply;  // set for call(): its caller waits on it
        int attempts = 0;                           // failed attempts at shutdown
    };
    // How one attempt at a write went, for the stats and the log.
    struct Attempt {
        bool done = false;
        std::optional<std::string> full, locked, fault;  // a wait-and-retry failure, by kind
        std::exception_ptr error;                        // what it threw, if anything
        std::string message;                             // its what(), for the log
        const std::optional<std::string>& waiting() const { return full ? full : locked ? locked : fault; }
    };
    static Attempt attempt(const std::function<void()>& write);
    void note_attempt_locked(const Attempt& a, bool sets_state);
    void run_call(const Job& fn);
    bool run_jobs(Database& db, std::unique_lock<std::mutex>& lock);  // false: the head waits for storage
    void fail_calls_locked(const std::exception_ptr& why);
    void open_crash_ring(Database& db);  // and store what a predecessor left in it
    void run(Database& db);
    void write_loop(Database& db);

    const std::filesystem::path path_;
    const RecorderOptions options_;
    const std::size_t wake_rows_;  // queue depth at which push() wakes the writer early

    mutable std::mutex mutex_;
    std::condition_variable wake_writer_;  // rows ready, flush asked, or stop
    std::condition_variable progress_;     // rows committed or lost, for flush()
    std::vector<SampleRow> queue_;         // reserved to queue_capacity; swapped with the writer's batch
    RecorderStats stats_;                  // queue_depth kept up to date under mutex_
    std::uint64_t resolved_ = 0;           // committed + duplicates + lost: accepted rows done so far
    std::uint64_t commit_attempts_ = 0;    // every attempt, for flush() to wait for the next one
    std::chrono::steady_clock::time_point first_row_at_{};  // when the queue last went from empty to one row
    std::deque<PendingJob> jobs_;          // posted and called writes, in order
    std::uint64_t jobs_posted_ = 0, jobs_resolved_ = 0;
    int flush_waiters_ = 0;
    bool stop_ = false;
    bool writer_gone_ = false;
    std::optional<CrashRing> ring_;        // appended by push(), trimmed as rows resolve (under mutex_)
    std::thread writer_;
};

}  // namespace manikind::recorder
