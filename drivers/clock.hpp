#pragma once
// Time for drivers: a monotonic and a UTC reading. The daemon uses the system clock; the
// simulated lab a clock it advances itself, so a 75-min trial runs in seconds and tests never
// sleep. Drivers take every timeout and backoff decision from this clock, never from sleeps.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>

namespace manikind::drivers {

class Clock {
public:
    virtual ~Clock() = default;
    virtual std::int64_t mono_ns() const = 0;
    virtual std::int64_t utc_ns() const = 0;
};

class SystemClock final : public Clock {
public:
    std::int64_t mono_ns() const override {
        return std::chrono::duration_cast<std::chrono::nanoseconds>(
                   std::chrono::steady_clock::now().time_since_epoch()).count();
    }
    std::int64_t utc_ns() const override {
        return std::chrono::duration_cast<std::chrono::nanoseconds>(
                   std::chrono::system_clock::now().time_since_epoch()).count();
    }
};

// Advanced explicitly (the simulated lab's virtual time). UTC = epoch + elapsed, until
// step_utc_ns() steps the wall clock alone, as NTP or someone setting the clock by hand does.
//
// Paced (set_pace: the simulated lab in real time, `--speed`): between two advances the clock
// runs on with the wall clock x speed, and each reading is later than the one before. Without
// it, every reading taken within one pacing step (1 s of virtual time at --speed 10) had the
// same stamp, and a late serial line took the stamp of the next and was skipped as a re-sent
// duplicate (issue 30: ~100 readings in 15 s under load).
class ManualClock final : public Clock {
public:
    explicit ManualClock(std::int64_t utc_epoch_ns = 1780304400LL * 1000000000LL) : utc_epoch_ns_(utc_epoch_ns) {}
    std::int64_t mono_ns() const override {
        const double speed = pace_.load();
        if (speed <= 0.0) return mono_ns_.load();
        const auto wall_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                 std::chrono::steady_clock::now().time_since_epoch()).count() - advanced_at_ns_.load();
        const std::int64_t t = mono_ns_.load() + static_cast<std::int64_t>(static_cast<double>(wall_ns) * speed);
        std::int64_t previous = last_read_ns_.load();
        for (;;) {  // strictly increasing, across threads
            const std::int64_t next = std::max(t, previous + 1);
            if (last_read_ns_.compare_exchange_weak(previous, next)) return next;
        }
    }
    std::int64_t utc_ns() const override { return utc_epoch_ns_.load() + mono_ns(); }
    void advance_ns(std::int64_t dt_ns) {
        mono_ns_ += dt_ns;
        advanced_at_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(
                              std::chrono::steady_clock::now().time_since_epoch()).count();
    }
    void step_utc_ns(std::int64_t dt_ns) { utc_epoch_ns_ += dt_ns; }
    void advance_s(double dt_s) { advance_ns(static_cast<std::int64_t>(dt_s * 1e9)); }
    double elapsed_s() const { return static_cast<double>(mono_ns_.load()) * 1e-9; }
    // From now on, run with the wall clock x speed between advances (0: stand still, the virtual clock).
    void set_pace(double speed) {
        advance_ns(0);
        pace_ = speed;
    }

private:
    std::atomic<std::int64_t> utc_epoch_ns_;
    std::atomic<std::int64_t> mono_ns_{0};
    std::atomic<double> pace_{0.0};
    std::atomic<std::int64_t> advanced_at_ns_{0};
    mutable std::atomic<std::int64_t> last_read_ns_{0};
};

}  // namespace manikind::drivers
