#include "daemon/alarm_book.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/core.h>

namespace manikind {

std::string AlarmEntry::state() const {
    if (shelved_until_utc_ns > 0) return "SHELVED";
    if (active) return acknowledged ? "ACKED" : "UNACK";
    return acknowledged ? "NORMAL" : "RTN_UNACK";
}

nlohmann::json AlarmEntry::to_json() const {
    auto ms = [](std::int64_t ns) -> nlohmann::json { return ns > 0 ? nlohmann::json(ns / 1000000) : nlohmann::json(nullptr); };
    return {{"id", id},
            {"utc_ms", raised_utc_ns / 1000000},
            {"last_utc_ms", last_utc_ns / 1000000},
            {"severity", severity == "error" ? "MAJOR" : "MINOR"},
            {"kind", kind},
            {"source", source},
            {"message", message},
            {"count", count},
            {"state", state()},
            {"active", active},
            {"acknowledged", acknowledged},
            {"acknowledged_by", acknowledged_by},
            {"acknowledged_utc_ms", ms(acknowledged_utc_ns)},
            {"cleared_utc_ms", ms(cleared_utc_ns)},
            {"cleared_message", cleared_message},
            {"shelved_until_utc_ms", ms(shelved_until_utc_ns)},
            {"shelved_by", shelved_by}};
}

std::int64_t AlarmBook::raise(const std::string& severity, const std::string& kind, const std::string& source,
                              const std::string& message, std::int64_t utc_ns, bool* new_alarm) {
    if (!source.empty()) {
        // The same condition still open (active, or returned but not yet acknowledged: it comes
        // back to UNACK, as ISA-18.2 has it): one line that counts, its severity the worst seen.
        const auto it = std::find_if(open_.begin(), open_.end(), [&](const AlarmEntry& a) { return a.kind == kind && a.source == source; });
        if (it != open_.end()) {
            if (!it->active) {
                it->active = true;
                it->acknowledged = false;
                it->acknowledged_by.clear();
                it->acknowledged_utc_ns = 0;
                it->cleared_utc_ns = 0;
                it->cleared_message.clear();
            }
            ++it->count;
            it->message = message;
            it->last_utc_ns = utc_ns;
            if (severity == "error") it->severity = "error";
            if (new_alarm) *new_alarm = false;
            return it->id;
        }
    }
    AlarmEntry a;
    a.id = next_id_++;
    a.severity = severity == "error" ? "error" : "warn";
    a.kind = kind;
    a.source = source;
    a.message = message;
    a.raised_utc_ns = a.last_utc_ns = utc_ns;
    // A one-shot has no condition to return: it is born returned, and waits for its acknowledgement.
    a.active = !source.empty();
    if (!a.active) a.cleared_utc_ns = utc_ns;
    open_.push_back(std::move(a));
    // Bounded: past the limit the oldest returned alarms close unacknowledged (kept in the history).
    while (open_.size() > kMaxOpen) {
        auto old = std::find_if(open_.begin(), open_.end(), [](const AlarmEntry& e) { return !e.active; });
        if (old == open_.end()) old = open_.begin();
        history_.push_back(std::move(*old));
        open_.erase(old);
        if (history_.size() > kMaxHistory) history_.pop_front();
    }
    if (new_alarm) *new_alarm = true;
    return open_.back().id;
}

void AlarmBook::close_if_done(std::deque<AlarmEntry>::iterator it) {
    if (it->active || !it->acknowledged || it->shelved_until_utc_ns > 0) return;
    history_.push_back(std::move(*it));
    open_.erase(it);
    if (history_.size() > kMaxHistory) history_.pop_front();
}

std::int64_t AlarmBook::clear(const std::string& kind, const std::string& source, const std::string& message, std::int64_t utc_ns) {
    const auto it = std::find_if(open_.begin(), open_.end(),
                                 [&](const AlarmEntry& a) { return a.active && a.kind == kind && a.source == source; });
    if (it == open_.end()) return 0;
    const std::int64_t id = it->id;
    it->active = false;
    it->cleared_utc_ns = utc_ns;
    it->cleared_message = message;
    close_if_done(it);
    return id;
}

std::string AlarmBook::acknowledge(std::int64_t id, const std::string& who, std::int64_t utc_ns) {
    const auto it = std::find_if(open_.begin(), open_.end(), [&](const AlarmEntry& a) { return a.id == id; });
    if (it == open_.end()) {
        if (std::any_of(history_.begin(), history_.end(), [&](const AlarmEntry& a) { return a.id == id; })) return {};
        return fmt::format("no alarm with id {}", id);
    }
    if (!it->acknowledged) {
        it->acknowledged = true;
        it->acknowledged_by = who;
        it->acknowledged_utc_ns = utc_ns;
    }
    close_if_done(it);
    return {};
}

std::string AlarmBook::shelve(std::int64_t id, double duration_s, const std::string& who, std::int64_t utc_ns) {
    if (!std::isfinite(duration_s) || duration_s <= 0.0 || duration_s > kMaxShelveS)
        return fmt::format("\"duration_s\": expected seconds in (0, {:.0f}] (a shelf ends by itself)", kMaxShelveS);
    const auto it = std::find_if(open_.begin(), open_.end(), [&](const AlarmEntry& a) { return a.id == id; });
    if (it == open_.end()) return fmt::format("no open alarm with id {}", id);
    it->shelved_until_utc_ns = utc_ns + static_cast<std::int64_t>(duration_s * 1e9);
    it->shelved_by = who;
    return {};
}

std::string AlarmBook::unshelve(std::int64_t id, const std::string& /*who*/) {
    const auto it = std::find_if(open_.begin(), open_.end(), [&](const AlarmEntry& a) { return a.id == id; });
    if (it == open_.end() || it->shelved_until_utc_ns == 0) return fmt::format("no shelved alarm with id {}", id);
    it->shelved_until_utc_ns = 0;
    it->shelved_by.clear();
    close_if_done(it);
    return {};
}

std::vector<std::int64_t> AlarmBook::expire_shelves(std::int64_t utc_ns) {
    std::vector<std::int64_t> back;
    for (auto& a : open_)
        if (a.shelved_until_utc_ns > 0 && utc_ns >= a.shelved_until_utc_ns) {
            a.shelved_until_utc_ns = 0;
            back.push_back(a.id);
        }
    for (const std::int64_t id : back) {
        const auto it = std::find_if(open_.begin(), open_.end(), [&](const AlarmEntry& a) { return a.id == id; });
        if (it != open_.end()) close_if_done(it);
    }
    return back;
}

nlohmann::json AlarmBook::open_json() const {
    nlohmann::json a = nlohmann::json::array();
    for (const auto& e : open_) a.push_back(e.to_json());
    return a;
}

nlohmann::json AlarmBook::history_json() const {
    nlohmann::json a = nlohmann::json::array();
    for (const auto& e : history_) a.push_back(e.to_json());
    return a;
}

const AlarmEntry* AlarmBook::find(std::int64_t id) const {
    for (const auto& e : open_)
        if (e.id == id) return &e;
    for (const auto& e : history_)
        if (e.id == id) return &e;
    return nullptr;
}

bool AlarmBook::active(const std::string& kind, const std::string& source) const {
    return std::any_of(open_.begin(), open_.end(), [&](const AlarmEntry& a) { return a.active && a.kind == kind && a.source == source; });
}

}  // namespace manikind
