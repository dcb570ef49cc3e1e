#pragma once
// What every driver shares: a name, counters visible in `manikin status`, and a periodic
// check() that the acquisition loop calls with the clock's time (stale detection, heartbeats,
// reconnect with backoff). A device that disappears degrades its samples; it never throws out
// of the driver and never blocks the others.
#include <cstdint>
#include <string>

#include "drivers/clock.hpp"
#include "drivers/sample.hpp"

namespace manikind::drivers {

struct DriverStatus {
    std::string name;
    std::string transport;              // "pty /dev/pts/3", "modbus-tcp 127.0.0.1:40123", ...
    bool connected = false;
    bool stale = false;
    std::uint64_t samples = 0;          // good samples delivered
    std::uint64_t frames = 0;           // frames / lines / responses decoded
    std::uint64_t checksum_errors = 0;  // checksum, signature or CRC failures
    std::uint64_t malformed = 0;        // framing or field errors, garbage bytes
    std::uint64_t timeouts = 0;         // no answer in time (Modbus) or silence past the stale limit
    std::uint64_t exceptions = 0;       // Modbus exception responses
    std::uint64_t reconnects = 0;       // successful re-opens after a loss
    std::uint64_t comm_errors = 0;      // failed reads/writes/opens
    std::uint64_t device_faults = 0;    // the device reports a fault (status code, diag word, bus-off)
    std::int64_t last_good_mono_ns = -1;
    std::string last_error;
};

// Exponential backoff for re-opening a lost connection: 0.5 s, 1 s, 2 s ... capped at 10 s.
class Backoff {
public:
    bool due(std::int64_t now_ns) const { return now_ns >= next_ns_; }
    void failed(std::int64_t now_ns) {
        next_ns_ = now_ns + delay_ns_;
        delay_ns_ = delay_ns_ * 2 > max_ns ? max_ns : delay_ns_ * 2;
    }
    void reset() { delay_ns_ = min_ns; next_ns_ = 0; }
    static constexpr std::int64_t min_ns = 500'000'000;
    static constexpr std::int64_t max_ns = 10'000'000'000;

private:
    std::int64_t delay_ns_ = min_ns;
    std::int64_t next_ns_ = 0;
};

class Driver {
public:
    virtual ~Driver() = default;
    virtual const std::string& name() const = 0;
    // Opens the transport (a failure is recorded and retried by check(), not thrown).
    virtual void start() = 0;
    virtual void stop() = 0;
    // Called by the acquisition loop at least once a second of (virtual) time.
    virtual void check(std::int64_t now_mono_ns) = 0;
    virtual DriverStatus status() const = 0;
};

}  // namespace manikind::drivers
