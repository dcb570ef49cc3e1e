#pragma once
// Time for drivers: a monotonic and a UTC reading. The daemon uses the system clock; the
// simulated lab a clock it advances itself, so a 75-min trial runs in seconds and tests never
// sleep. Drivers take every timeout and backoff decision from this clock, never from sleeps.
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
class ManualClock final : public Clock {
public:
    explicit ManualClock(std::int64_t utc_epoch_ns = 1780304400LL * 1000000000LL) : utc_epoch_ns_(utc_epoch_ns) {}
    std::int64_t mono_ns() const override { return mono_ns_.load(); }
    std::int64_t utc_ns() const override { return utc_epoch_ns_.load() + mono_ns_.load(); }
    void advance_ns(std::int64_t dt_ns) { mono_ns_ += dt_ns; }
    void step_utc_ns(std::int64_t dt_ns) { utc_epoch_ns_ += dt_ns; }
    void advance_s(double dt_s) { advance_ns(static_cast<std::int64_t>(dt_s * 1e9)); }
    double elapsed_s() const { return static_cast<double>(mono_ns_.load()) * 1e-9; }

private:
    std::atomic<std::int64_t> utc_epoch_ns_;
    std::atomic<std::int64_t> mono_ns_{0};
};

}  // namespace manikind::drivers
