#include "store/recorder.hpp"

#include <algorithm>
#include <exception>
#include <future>
#include <optional>
#include <utility>

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
    }
    // Wake the writer only on the transitions it waits for, not per row.
    if (depth == 1 || depth == wake_rows_) wake_writer_.notify_one();
    return true;
}

bool Recorder::flush() {
    std::unique_lock lock(mutex_);
    const std::uint64_t target = stats_.accepted;
    if (resolved_ >= target) return true;
    const std::uint64_t attempts_before = commit_attempts_;
    ++flush_waiters_;
    wake_writer_.notify_one();
    // A full disk or a lock held elsewhere: one more attempt is enough to know (waiting for
    // space, or for an analyst to close a transaction, could take hours).
    progress_.wait(lock, [&] {
        return resolved_ >= target || writer_gone_ ||
               ((stats_.storage_full || stats_.locked) && commit_attempts_ > attempts_before);
    });
    --flush_waiters_;
    return resolved_ >= target;
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
    progress_.notify_all();
}

void Recorder::write_loop(Database& db) {
    const std::size_t chunk_rows = std::max<std::size_t>(1, options_.max_batch_rows);
    std::vector<SampleRow> batch;
    batch.reserve(options_.queue_capacity);
    std::size_t done = 0;  // rows of batch committed or lost
    int attempts = 0;      // failed attempts at the current chunk
    Clock::time_point taken_at = Clock::now();

    std::unique_lock lock(mutex_);
    for (;;) {
        if (done == batch.size()) {
            batch.clear();
            done = 0;
            if (queue_.empty()) {
                if (stop_) return;
                wake_writer_.wait(lock, [&] { return stop_ || !queue_.empty(); });
                if (queue_.empty()) continue;
                taken_at = Clock::now();  // the first row just arrived
            }
            // Every row now queued arrived after taken_at, so none waits longer than the delay.
            wake_writer_.wait_until(lock, taken_at + options_.max_batch_delay, [&] {
                return stop_ || flush_waiters_ > 0 || queue_.size() >= wake_rows_;
            });
            std::swap(queue_, batch);  // both keep their reserved capacity
            taken_at = Clock::now();
        }
        lock.unlock();

        const std::size_t n = std::min(chunk_rows, batch.size() - done);
        const auto t0 = Clock::now();
        bool committed = false;
        std::size_t duplicates = 0;
        std::optional<std::string> full;    // the disk is full: say so, and wait for space
        std::optional<std::string> locked;  // another connection holds the lock: likewise, for it
        try {
            duplicates = db.insert_samples(std::span<const SampleRow>(batch.data() + done, n));
            committed = true;
        } catch (const StorageFull& e) {
            full = e.what();
        } catch (const StorageBusy& e) {
            locked = e.what();
        } catch (const std::exception& e) {
            spdlog::error("recorder: commit of {} rows failed (attempt {} of {}): {}", n, attempts + 1,
                          options_.max_commit_attempts, e.what());
        }
        const double commit_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        bool was_full = false, was_locked = false, stopping = false;
        {
            std::lock_guard peek(mutex_);
            was_full = stats_.storage_full;
            was_locked = stats_.locked;
            stopping = stop_;
        }
        if (full && !was_full) spdlog::error("recorder: disk full, {} rows kept in memory until space returns: {}", n, *full);
        if (committed && was_full) spdlog::warn("recorder: space is back, recording resumed");
        if (locked && !was_locked)
            spdlog::error("recorder: the database is locked by another connection (a write, or with journal = rollback a "
                          "read transaction left open); {} rows kept in memory until it lets go: {}", n, *locked);
        if (committed && was_locked) spdlog::warn("recorder: the lock was released, recording resumed");
        const std::optional<std::string>& waiting = full ? full : locked;
        if (waiting && stopping) {
            spdlog::error("recorder: commit of {} rows failed at shutdown (attempt {} of {}): {}", n, attempts + 1,
                          options_.max_commit_attempts, *waiting);
        }
        if (!committed && (!waiting || stopping)) ++attempts;
        const bool give_up = !committed && attempts >= options_.max_commit_attempts;
        // Logged before taking the lock: a slow stderr must not hold up push().
        if (duplicates > 0) spdlog::warn("recorder: {} rows skipped, already stored (re-sent readings?)", duplicates);
        if (give_up) spdlog::error("recorder: {} rows discarded after {} failed commits", n, attempts);

        lock.lock();
        ++commit_attempts_;
        stats_.storage_full = full.has_value();
        if (full) {
            stats_.storage_error = *full;
            ++stats_.full_disk_commits;
        }
        stats_.locked = locked.has_value();
        if (locked) ++stats_.locked_commits;
        if (committed) {
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
