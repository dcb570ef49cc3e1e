#include "store/recorder.hpp"

#include <algorithm>
#include <exception>
#include <future>
#include <optional>
#include <utility>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

namespace manikind::recorder {

using Clock = std::chrono::steady_clock;

Recorder::Recorder(std::filesystem::path db_path, RecorderOptions options)
    : path_(std::move(db_path)),
      options_(options),
      // Half the queue, so the writer is already busy well before push() starts dropping.
      wake_rows_(std::max<std::size_t>(1, std::min(options.max_batch_rows, options.queue_capacity / 2))) {
    queue_.reserve(options_.queue_capacity);
    std::promise<void> opened;
    auto opened_future = opened.get_future();
    // The connection is opened, used and closed in the writer thread only.
    writer_ = std::thread([this, opened = std::move(opened)]() mutable {
        std::optional<Database> db;
        try {
            db.emplace(Database::open(path_, options_.durability, options_.journal));
            db->check_sample_keys_here();  // this connection only inserts samples
            stats_.journal = db->journal_mode();  // before the constructor returns: no reader yet
            db->set_busy_timeout(options_.lock_timeout);
            open_crash_ring(*db);
        } catch (...) {
            opened.set_exception(std::current_exception());
            return;
        }
        opened.set_value();
        run(*db);
    });
    try {
        opened_future.get();
    } catch (...) {
        writer_.join();
        throw;
    }
}

Recorder::~Recorder() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_writer_.notify_one();
    writer_.join();
    // Everything stored: nothing for a successor to recover, so leave no file behind.
    if (ring_ && ring_->pending().empty()) {
        std::error_code ec;
        std::filesystem::remove(ring_->path(), ec);
    }
}

void Recorder::open_crash_ring(Database& db) {
    if (options_.crash_ring_dir.empty()) return;
    std::string why_not;
    // Rows wait in the queue or in the batch being written, each at most queue_capacity.
    ring_ = CrashRing::open(options_.crash_ring_dir, path_, 2 * options_.queue_capacity, why_not);
    if (!ring_) {
        spdlog::warn("recorder: no crash ring ({}); samples not yet committed are lost if the daemon dies", why_not);
        return;
    }
    stats_.crash_ring = ring_->path().string();
    auto left = ring_->pending();
    if (left.empty()) return;
    const std::size_t found = left.size();
    // Readings committed just before the crash, before the ring was trimmed: one scan a trial.
    std::size_t already = db.remove_already_stored(left);
    // A predecessor died with these uncommitted. Stored before any new row; a reading already
    // stored (it died between its commit and trimming the ring) is skipped as a duplicate, and
    // rows whose trial or channel is gone are reported, not kept for ever.
    const std::size_t chunk = std::max<std::size_t>(1, options_.max_batch_rows);
    std::size_t stored = 0, unusable = 0;
    for (std::size_t at = 0; at < left.size(); at += chunk) {
        const std::span<const SampleRow> rows(left.data() + at, std::min(chunk, left.size() - at));
        try {
            const std::size_t skipped = db.insert_samples(rows);
            stored += rows.size() - skipped;
            already += skipped;
        } catch (const std::exception&) {
            // One bad row fails its transaction: store the chunk row by row (a rare path).
            for (const auto& row : rows) {
                try {
                    const std::size_t skipped = db.insert_samples(std::span<const SampleRow>(&row, 1));
                    stored += 1 - skipped;
                    already += skipped;
                } catch (const std::exception& e) {
                    if (unusable++ == 0) spdlog::error("recorder: a sample from the crash ring cannot be stored: {}", e.what());
                }
            }
        }
    }
    ring_->clear();
    stats_.recovered = stored;
    spdlog::warn("recorder: stored {} of {} samples that a stopped daemon had not committed ({} already stored, {} "
                 "unusable), from {}",
                 stored, found, already, unusable, ring_->path().string());
}

bool Recorder::push(const SampleRow& row) noexcept {
    if (offer(row)) return true;
    std::lock_guard lock(mutex_);
    ++stats_.dropped;
    return false;
}

bool Recorder::offer(const SampleRow& row) noexcept {
    std::size_t depth = 0;
    {
        std::lock_guard lock(mutex_);
        if (queue_.size() >= options_.queue_capacity) return false;
        queue_.push_back(row);  // within the reserved capacity: no allocation
        if (ring_) ring_->append(row);
        ++stats_.accepted;
        ++stats_.queue_depth;
        depth = queue_.size();
        if (depth == 1) first_row_at_ = Clock::now();
    }
    // Wake the writer only on the transitions it waits for, not per row.
    if (depth == 1 || depth == wake_rows_) wake_writer_.notify_one();
    return true;
}

std::size_t Recorder::offer_many(std::span<const SampleRow> rows) noexcept {
    if (rows.empty()) return 0;
    std::size_t taken = 0, before = 0, depth = 0;
    {
        std::lock_guard lock(mutex_);
        before = queue_.size();
        taken = std::min(rows.size(), options_.queue_capacity - std::min(options_.queue_capacity, before));
        for (std::size_t i = 0; i < taken; ++i) {
            queue_.push_back(rows[i]);  // within the reserved capacity: no allocation
            if (ring_) ring_->append(rows[i]);
        }
        stats_.accepted += taken;
        stats_.queue_depth += taken;
        depth = queue_.size();
        if (before == 0 && taken > 0) first_row_at_ = Clock::now();
    }
    // The same transitions offer() wakes the writer on: the first row, or reaching wake_rows_.
    if (taken > 0 && (before == 0 || (before < wake_rows_ && depth >= wake_rows_))) wake_writer_.notify_one();
    return taken;
}

bool Recorder::post(Job job) {
    {
        std::lock_guard lock(mutex_);
        if (writer_gone_ || jobs_.size() >= options_.max_jobs) {
            ++stats_.jobs_lost;
            return false;
        }
        jobs_.push_back({std::move(job), nullptr, 0});
        ++jobs_posted_;
        stats_.jobs_waiting = jobs_.size();
    }
    wake_writer_.notify_one();
    return true;
}

void Recorder::run_call(const Job& fn) {
    auto reply = std::make_shared<std::promise<void>>();
    auto answer = reply->get_future();
    {
        std::lock_guard lock(mutex_);
        if (writer_gone_) throw UserError(fmt::format("{}: the recorder's writer has stopped", path_.string()), "storage_error");
        // The writer waits on storage: say so now rather than queue behind the writes that wait.
        if (stats_.storage_full) throw StorageFull(stats_.storage_error);
        if (stats_.locked) throw StorageBusy(stats_.storage_error);
        if (stats_.io_error) throw StorageFault(stats_.storage_error);
        // The caller waits on `answer` before returning, so `fn` outlives the job.
        jobs_.push_back({[&fn](Database& db) { fn(db); }, reply, 0});
        ++jobs_posted_;
        stats_.jobs_waiting = jobs_.size();
    }
    wake_writer_.notify_one();
    answer.get();  // rethrows what fn threw
}

bool Recorder::flush() {
    std::unique_lock lock(mutex_);
    const std::uint64_t target = stats_.accepted;
    const std::uint64_t jobs_target = jobs_posted_;
    if (resolved_ >= target && jobs_resolved_ >= jobs_target) return true;
    const std::uint64_t attempts_before = commit_attempts_;
    ++flush_waiters_;
    wake_writer_.notify_one();
    // A full disk, a lock held elsewhere or a failing file system: one more attempt is enough to
    // know (waiting for space, or for an analyst to close a transaction, could take hours).
    progress_.wait(lock, [&] {
        return (resolved_ >= target && jobs_resolved_ >= jobs_target) || writer_gone_ ||
               ((stats_.storage_full || stats_.locked || stats_.io_error) && commit_attempts_ > attempts_before);
    });
    --flush_waiters_;
    return resolved_ >= target && jobs_resolved_ >= jobs_target;
}

RecorderStats Recorder::stats() const {
    std::lock_guard lock(mutex_);
    return stats_;
}

void Recorder::run(Database& db) {
    try {
        write_loop(db);
    } catch (const std::exception& e) {
        spdlog::error("recorder {}: writer stopped: {}", path_.string(), e.what());
    } catch (...) {
        spdlog::error("recorder {}: writer stopped by an unknown exception", path_.string());
    }
    std::lock_guard lock(mutex_);
    writer_gone_ = true;
    fail_calls_locked(std::make_exception_ptr(UserError(fmt::format("{}: the recorder's writer has stopped", path_.string()),
                                                        "storage_error")));
    progress_.notify_all();
}

Recorder::Attempt Recorder::attempt(const std::function<void()>& write) {
    Attempt a;
    try {
        write();
        a.done = true;
    } catch (const StorageFull& e) {
        a.full = a.message = e.what();
        a.error = std::current_exception();
    } catch (const StorageBusy& e) {
        a.locked = a.message = e.what();
        a.error = std::current_exception();
    } catch (const StorageFault& e) {
        a.fault = a.message = e.what();
        a.error = std::current_exception();
    } catch (const std::exception& e) {
        a.message = e.what();
        a.error = std::current_exception();
    } catch (...) {
        a.message = "an exception that is not a std::exception";
        a.error = std::current_exception();
    }
    return a;
}

// The storage state is what the latest sample commit or posted write met: those are tried again
// each second, so it stays fresh. A call() is tried once, so its failure only counts.
void Recorder::note_attempt_locked(const Attempt& a, bool sets_state) {
    ++commit_attempts_;
    if (a.full) ++stats_.full_disk_commits;
    if (a.locked) ++stats_.locked_commits;
    if (a.fault) ++stats_.io_error_commits;
    if (!sets_state && !a.done) return;
    stats_.storage_full = a.full.has_value();
    stats_.locked = a.locked.has_value();
    stats_.io_error = a.fault.has_value();
    if (const auto& w = a.waiting()) stats_.storage_error = *w;
}

namespace {
// Said once per episode, outside the lock: a slow stderr must not hold up push().
void log_transition(const std::string& path, bool done, const std::optional<std::string>& full,
                    const std::optional<std::string>& locked, const std::optional<std::string>& fault, bool was_full, bool was_locked, bool was_fault) {
    if (full && !was_full) spdlog::error("recorder: disk full; readings and writes kept in memory until space returns: {}", *full);
    if (done && was_full) spdlog::warn("recorder: space is back, recording resumed");
    if (locked && !was_locked)
        spdlog::error("recorder: the database is locked by another connection (a write, or with journal = rollback a "
                      "read transaction left open); readings and writes kept in memory until it lets go: {}", *locked);
    if (done && was_locked) spdlog::warn("recorder: the lock was released, recording resumed");
    if (fault && !was_fault)
        spdlog::error("recorder: {}: the file system failed a write; readings and writes kept in memory, tried again "
                      "each second: {}", path, *fault);
    if (done && was_fault) spdlog::warn("recorder: the file system writes again, recording resumed");
}
}  // namespace

// Writes waiting for storage fail a call() at once (its caller tries again later); posted
// writes stay in line.
void Recorder::fail_calls_locked(const std::exception_ptr& why) {
    for (auto it = jobs_.begin(); it != jobs_.end();) {
        if (it->reply) {
            it->reply->set_exception(why);
            it = jobs_.erase(it);
            ++jobs_resolved_;
        } else {
            ++it;
        }
    }
    stats_.jobs_waiting = jobs_.size();
}

bool Recorder::run_jobs(Database& db, std::unique_lock<std::mutex>& lock) {
    while (!jobs_.empty()) {
        PendingJob job = std::move(jobs_.front());
        jobs_.pop_front();
        const bool was_full = stats_.storage_full, was_locked = stats_.locked, was_fault = stats_.io_error;
        const bool stopping = stop_;
        lock.unlock();
        const Attempt a = attempt([&] { job.run(db); });
        if (!job.reply || a.done) log_transition(path_.string(), a.done, a.full, a.locked, a.fault, was_full, was_locked, was_fault);
        const bool waits = a.waiting().has_value() && !job.reply;
        const bool give_up = waits && stopping && job.attempts + 1 >= options_.max_commit_attempts;
        if (give_up) spdlog::error("recorder: a write (event or state) discarded at shutdown after {} attempts: {}",
                                   job.attempts + 1, *a.waiting());
        if (!a.done && !a.waiting() && !job.reply)
            spdlog::error("recorder: a write (event or state) failed and is not kept: {}", a.message);
        lock.lock();
        note_attempt_locked(a, !job.reply);
        if (waits && !give_up) {
            if (stopping) ++job.attempts;
            jobs_.push_front(std::move(job));  // first in line when storage is back
            fail_calls_locked(a.error);
            progress_.notify_all();
            return false;
        }
        if (job.reply) {
            if (a.done) job.reply->set_value();
            else job.reply->set_exception(a.error);
        }
        if (a.done) ++stats_.jobs_done;
        else if (give_up) ++stats_.jobs_lost;
        else if (!job.reply) ++stats_.jobs_failed;
        ++jobs_resolved_;
        stats_.jobs_waiting = jobs_.size();
        progress_.notify_all();
    }
    return true;
}

void Recorder::write_loop(Database& db) {
    const std::size_t chunk_rows = std::max<std::size_t>(1, options_.max_batch_rows);
    std::vector<SampleRow> batch;
    batch.reserve(options_.queue_capacity);
    std::size_t done = 0;  // rows of batch committed or lost
    int attempts = 0;      // failed attempts at the current chunk

    std::unique_lock lock(mutex_);
    for (;;) {
        if (done == batch.size()) {
            batch.clear();
            done = 0;
            // Other writes first: they are few and small, and a call() has a caller waiting.
            if (!jobs_.empty()) {
                if (!run_jobs(db, lock))
                    wake_writer_.wait_for(lock, options_.full_disk_retry, [&] { return stop_ || flush_waiters_ > 0; });
                continue;
            }
            if (queue_.empty()) {
                if (stop_) return;
                wake_writer_.wait(lock, [&] { return stop_ || !queue_.empty() || !jobs_.empty(); });
                continue;
            }
            // Every row now queued arrived after first_row_at_, so none waits longer than the delay.
            const auto deadline = first_row_at_ + options_.max_batch_delay;
            wake_writer_.wait_until(lock, deadline, [&] {
                return stop_ || flush_waiters_ > 0 || queue_.size() >= wake_rows_ || !jobs_.empty();
            });
            if (!jobs_.empty() && !stop_ && flush_waiters_ == 0 && queue_.size() < wake_rows_ && Clock::now() < deadline)
                continue;  // a write came first: make it, then go on waiting for rows
            std::swap(queue_, batch);  // both keep their reserved capacity
        }
        const bool was_full = stats_.storage_full, was_locked = stats_.locked, was_fault = stats_.io_error;
        const bool stopping = stop_;
        lock.unlock();

        const std::size_t n = std::min(chunk_rows, batch.size() - done);
        const auto t0 = Clock::now();
        std::size_t duplicates = 0;
        const Attempt a = attempt([&] { duplicates = db.insert_samples(std::span<const SampleRow>(batch.data() + done, n)); });
        const double commit_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        log_transition(path_.string(), a.done, a.full, a.locked, a.fault, was_full, was_locked, was_fault);
        const std::optional<std::string>& waiting = a.waiting();
        if (!a.done && (!waiting || stopping)) {
            spdlog::error("recorder: commit of {} rows failed{} (attempt {} of {}): {}", n, stopping ? " at shutdown" : "",
                          attempts + 1, options_.max_commit_attempts, a.message);
            ++attempts;
        }
        const bool give_up = !a.done && attempts >= options_.max_commit_attempts;
        // Logged before taking the lock: a slow stderr must not hold up push().
        if (duplicates > 0) spdlog::warn("recorder: {} rows skipped, already stored (re-sent readings?)", duplicates);
        if (give_up) spdlog::error("recorder: {} rows discarded after {} failed commits", n, attempts);

        lock.lock();
        note_attempt_locked(a, true);
        if (waiting) fail_calls_locked(a.error);
        if (a.done) {
            stats_.committed += n - duplicates;
            stats_.duplicates += duplicates;
            ++stats_.batches;
            stats_.max_commit_ms = std::max(stats_.max_commit_ms, commit_ms);
        } else {
            ++stats_.failed_commits;
            if (!give_up) {
                // Keep the rows and retry after a pause (cut short at shutdown, and by a flush
                // while the disk is full), since a full disk or a lock held elsewhere rarely
                // clears in microseconds.
                progress_.notify_all();  // a flush() waiting on a full disk has its answer
                if (waiting)
                    wake_writer_.wait_for(lock, options_.full_disk_retry, [&] { return stop_ || flush_waiters_ > 0; });
                else
                    wake_writer_.wait_for(lock, options_.max_batch_delay, [&] { return stop_; });
                continue;
            }
            stats_.lost += n;
        }
        attempts = 0;
        done += n;
        resolved_ += n;
        if (ring_) ring_->resolved(n);
        stats_.queue_depth -= n;
        progress_.notify_all();
    }
}

}  // namespace manikind::recorder
