// The alarm life cycle (daemon/alarm_book.hpp, issue 35): ISA-18.2's states from raise, clear,
// acknowledge and shelve, in both orders, with the repeats that used to pile up.
#include <catch2/catch.hpp>

#include "daemon/alarm_book.hpp"

using manikind::AlarmBook;

namespace {
constexpr std::int64_t kSecondNs = 1'000'000'000;  // one second in ns

std::string state_of(const AlarmBook& b, std::int64_t id) {
    const auto* a = b.find(id);
    return a ? a->state() : "missing";
}
}  // namespace

TEST_CASE("alarm book: a condition alarm goes UNACK, ACKED, then closes when it returns", "[daemon][alarms]") {
    AlarmBook b;
    const auto id = b.raise("warn", "gap", "chamber", "chamber lost (stale)", 10 * kSecondNs);
    CHECK(state_of(b, id) == "UNACK");
    CHECK(b.acknowledge(id, "ana", 12 * kSecondNs).empty());
    CHECK(state_of(b, id) == "ACKED");
    CHECK(b.find(id)->acknowledged_by == "ana");
    CHECK(b.open_json().size() == 1);
    CHECK(b.clear("gap", "chamber", "chamber back after 30 s", 40 * kSecondNs) == id);
    CHECK(state_of(b, id) == "NORMAL");
    CHECK(b.open_json().empty());
    REQUIRE(b.history_json().size() == 1);
    CHECK(b.history_json()[0]["cleared_message"] == "chamber back after 30 s");
    CHECK(b.history_json()[0]["acknowledged_by"] == "ana");
}

TEST_CASE("alarm book: returned before anyone saw it, it waits as RTN_UNACK, and the acknowledgement closes it",
          "[daemon][alarms]") {
    AlarmBook b;
    const auto id = b.raise("error", "database_locked", "database", "locked", 1 * kSecondNs);
    CHECK(b.clear("database_locked", "database", "free again", 5 * kSecondNs) == id);
    CHECK(state_of(b, id) == "RTN_UNACK");
    CHECK(b.open_json().size() == 1);
    CHECK(b.open_json()[0]["state"] == "RTN_UNACK");
    CHECK(b.acknowledge(id, "bo", 9 * kSecondNs).empty());
    CHECK(b.open_json().empty());
    CHECK(state_of(b, id) == "NORMAL");
    // Clearing what is not active changes nothing.
    CHECK(b.clear("database_locked", "database", "again", 10 * kSecondNs) == 0);
}

TEST_CASE("alarm book: a device that drops out again and again is one alarm that counts, not a pile", "[daemon][alarms]") {
    AlarmBook b;
    std::int64_t first = 0;
    for (int episode = 0; episode < 50; ++episode) {
        bool fresh = false;
        const auto id = b.raise("warn", "gap", "windsonic", "windsonic lost (stale)", (100 * episode + 1) * kSecondNs, &fresh);
        if (episode == 0) first = id;
        CHECK(id == first);
        CHECK(fresh == (episode == 0));
        b.clear("gap", "windsonic", "windsonic back", (100 * episode + 50) * kSecondNs);
    }
    REQUIRE(b.open_json().size() == 1);
    CHECK(b.open_json()[0]["count"] == 50);
    CHECK(b.open_json()[0]["state"] == "RTN_UNACK");
    // Another device is another alarm; an error raises the severity of the line.
    const auto other = b.raise("warn", "gap", "chamber", "chamber lost", 6000 * kSecondNs);
    CHECK(other != first);
    b.raise("error", "gap", "chamber", "chamber lost (disconnected)", 6001 * kSecondNs);
    CHECK(b.find(other)->severity == "error");
    CHECK(b.find(other)->message == "chamber lost (disconnected)");
    CHECK(b.find(other)->count == 2);
}

TEST_CASE("alarm book: a one-shot is born returned and closes when acknowledged", "[daemon][alarms]") {
    AlarmBook b;
    const auto id = b.raise("warn", "abort", "", "'c' aborted by ana: probe fell off", 3 * kSecondNs);
    const auto again = b.raise("warn", "abort", "", "'d' aborted by ana: wrong ensemble", 4 * kSecondNs);
    CHECK(id != again);  // one-shots are separate events, never merged
    CHECK(state_of(b, id) == "RTN_UNACK");
    CHECK(b.acknowledge(id, "ana", 5 * kSecondNs).empty());
    CHECK(state_of(b, id) == "NORMAL");
    CHECK(b.acknowledge(id, "ana", 6 * kSecondNs).empty());  // twice is harmless
    CHECK(b.acknowledge(424242, "ana", 6 * kSecondNs).find("no alarm with id 424242") != std::string::npos);
}

TEST_CASE("alarm book: a shelf is bounded, hides the alarm, and ends by itself", "[daemon][alarms]") {
    AlarmBook b;
    const auto id = b.raise("warn", "gap", "csat3b", "csat3b lost", 0);
    CHECK_FALSE(b.shelve(id, 0.0, "ana", kSecondNs).empty());
    CHECK_FALSE(b.shelve(id, -5.0, "ana", kSecondNs).empty());
    CHECK_FALSE(b.shelve(id, 9 * 3600.0, "ana", kSecondNs).empty());  // beyond 8 h
    CHECK_FALSE(b.shelve(id, std::numeric_limits<double>::quiet_NaN(), "ana", kSecondNs).empty());
    CHECK(b.shelve(id, 600.0, "ana", kSecondNs).empty());
    CHECK(state_of(b, id) == "SHELVED");
    // Returning and acknowledging while shelved keeps it on the shelf until the shelf ends.
    b.clear("gap", "csat3b", "csat3b back", 100 * kSecondNs);
    CHECK(b.acknowledge(id, "ana", 101 * kSecondNs).empty());
    CHECK(state_of(b, id) == "SHELVED");
    CHECK(b.expire_shelves(600 * kSecondNs).empty());           // not yet: shelved at 1 s for 600 s
    CHECK(b.expire_shelves(601 * kSecondNs) == std::vector<std::int64_t>{id});
    CHECK(state_of(b, id) == "NORMAL");                  // returned and acknowledged: closed
    const auto other = b.raise("warn", "gap", "chamber", "chamber lost", 700 * kSecondNs);
    CHECK(b.shelve(other, 60.0, "bo", 700 * kSecondNs).empty());
    CHECK(b.unshelve(other, "bo").empty());
    CHECK(state_of(b, other) == "UNACK");
    CHECK_FALSE(b.unshelve(other, "bo").empty());
}

TEST_CASE("alarm book: bounded however many alarms come", "[daemon][alarms]") {
    AlarmBook b;
    for (int i = 0; i < 2000; ++i) b.raise("warn", "excursion", "", "air off its setpoint", i * kSecondNs);
    CHECK(b.open_json().size() == AlarmBook::kMaxOpen);
    CHECK(b.history_json().size() == AlarmBook::kMaxHistory);
    // The newest are the ones kept open.
    CHECK(b.open_json().back()["utc_ms"] == 1999 * 1000);
}
