#pragma once
// One job on a persistent thread, started and awaited once per virtual step. The lockstep stays
// exact (the job runs between start() and wait(), on the state of this step), but it overlaps
// what the caller does in between: in Acquisition::step, the datalogger's Modbus round trips
// overlap the chamber's and the manikin bus reads instead of following them. A thread per step
// would cost more than the work it overlaps.
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>

namespace manikind {

class StepWorker {
public:
    explicit StepWorker(std::function<void()> job) : job_(std::move(job)), thread_([this] { run(); }) {}
    ~StepWorker() {
        {
            std::lock_guard lk(lock_);
            stop_ = true;
        }
        changed_.notify_all();
        thread_.join();
    }
    StepWorker(const StepWorker&) = delete;
    StepWorker& operator=(const StepWorker&) = delete;

    // Runs the job once on the worker; call wait() before the next start().
    void start() {
        {
            std::lock_guard lk(lock_);
            pending_ = true;
        }
        changed_.notify_all();
    }
    // Until the job last started has returned; rethrows what it threw.
    void wait() {
        std::unique_lock lk(lock_);
        changed_.wait(lk, [this] { return !pending_; });
        if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
    }

private:
    void run() {
        std::unique_lock lk(lock_);
        for (;;) {
            changed_.wait(lk, [this] { return pending_ || stop_; });
            if (stop_) return;
            lk.unlock();
            std::exception_ptr error;
            try {
                job_();
            } catch (...) {
                error = std::current_exception();
            }
            lk.lock();
            error_ = error;
            pending_ = false;
            changed_.notify_all();
        }
    }

    std::function<void()> job_;
    std::mutex lock_;
    std::condition_variable changed_;
    bool pending_ = false;
    bool stop_ = false;
    std::exception_ptr error_;
    std::thread thread_;  // last: it starts once every member it uses exists
};

}  // namespace manikind
