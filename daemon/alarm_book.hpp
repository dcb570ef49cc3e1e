#pragma once
// Alarms with a life cycle (issue 35; ISA-18.2's states, as EPICS alarm handlers show them):
//
//   UNACK      the condition is active and nobody has acknowledged it
//   ACKED      active, acknowledged (someone is on it)
//   RTN_UNACK  the condition has returned to normal, but nobody has acknowledged it yet
//   SHELVED    hidden by an operator for a bounded time (it comes back by itself)
//   NORMAL     returned and acknowledged: the alarm is closed and moves to the history
//
// A condition alarm has a source (the device that went stale, the database that is locked): it
// is raised once while the condition lasts (raised again, it counts, not a new line; raised
// again after it returned but before anyone acknowledged it, the same line is active again) and
// cleared when the condition returns. A one-shot alarm (an abort, a safety trip, a failed computation)
// has no condition to return: it is born returned and needs only an acknowledgement.
// No I/O and no clock: times are passed in, so every rule here is unit-tested.
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace manikind {

struct AlarmEntry {
    std::int64_t id = 0;
    std::string severity;          // "warn" (MINOR) or "error" (MAJOR)
    std::string kind, source;      // source empty: a one-shot
    std::string message;           // the latest
    std::int64_t raised_utc_ns = 0, last_utc_ns = 0;
    int count = 1;                 // times raised while active
    bool active = true;
    bool acknowledged = false;
    std::string acknowledged_by;
    std::int64_t acknowledged_utc_ns = 0;
    std::int64_t cleared_utc_ns = 0;
    std::string cleared_message;
    std::int64_t shelved_until_utc_ns = 0;  // 0: not shelved
    std::string shelved_by;

    std::string state() const;     // UNACK, ACKED, RTN_UNACK, SHELVED, NORMAL
    nlohmann::json to_json() const;
};

class AlarmBook {
public:
    static constexpr std::size_t kMaxOpen = 500;       // beyond: the oldest returned one-shots close
    static constexpr std::size_t kMaxHistory = 500;
    static constexpr double kMaxShelveS = 8 * 3600.0;  // a shelf is a bounded promise

    // Returns the alarm's id; `new_alarm` says whether it is a new line (not a repeat of an active one).
    std::int64_t raise(const std::string& severity, const std::string& kind, const std::string& source,
                       const std::string& message, std::int64_t utc_ns, bool* new_alarm = nullptr);
    // The condition (kind, source) returned. Returns the id cleared, or 0 when none was active.
    std::int64_t clear(const std::string& kind, const std::string& source, const std::string& message, std::int64_t utc_ns);
    // Each returns an error message, empty when done.
    std::string acknowledge(std::int64_t id, const std::string& who, std::int64_t utc_ns);
    std::string shelve(std::int64_t id, double duration_s, const std::string& who, std::int64_t utc_ns);
    std::string unshelve(std::int64_t id, const std::string& who);
    // Shelves past their time end; returns the ids that came back.
    std::vector<std::int64_t> expire_shelves(std::int64_t utc_ns);

    // Open alarms (not NORMAL), oldest first; and the closed ones, newest last.
    nlohmann::json open_json() const;
    nlohmann::json history_json() const;
    const AlarmEntry* find(std::int64_t id) const;
    bool active(const std::string& kind, const std::string& source) const;

private:
    void close_if_done(std::deque<AlarmEntry>::iterator it);
    std::deque<AlarmEntry> open_;
    std::deque<AlarmEntry> history_;
    std::int64_t next_id_ = 1;
};

}  // namespace manikind
