// The simulated lab's clock (drivers/clock.hpp). On the virtual clock it stands still between
// steps (the lockstep stamps every reading of a step alike, by design). Paced (--speed), it runs
// on with the wall clock between the pacing steps, and no two readings share a stamp: a serial
// line read late used to take the next one's stamp and was dropped as a re-sent duplicate.
#include <catch2/catch.hpp>

#include <algorithm>
#include <thread>
#include <vector>

#include "drivers/clock.hpp"

using manikind::drivers::ManualClock;

TEST_CASE("clock: the virtual clock stands still between steps, utc follows mono", "[clock]") {
    ManualClock c(1'000'000'000'000);
    CHECK(c.mono_ns() == 0);
    CHECK(c.mono_ns() == 0);
    c.advance_s(1.5);
    CHECK(c.mono_ns() == 1'500'000'000);
    CHECK(c.utc_ns() == 1'000'000'000'000 + 1'500'000'000);
}

TEST_CASE("clock: paced, every reading is later than the one before, from any thread, and steps still add", "[clock]") {
    ManualClock c;
    c.advance_s(10.0);
    c.set_pace(10.0);
    const std::int64_t start = c.mono_ns();
    CHECK(start >= 10'000'000'000);
    constexpr int per_thread = 20000;
    std::vector<std::vector<std::int64_t>> seen(2);
    {
        std::vector<std::thread> readers;
        for (auto& out : seen)
            readers.emplace_back([&c, &out] {
                out.reserve(per_thread);
                for (int i = 0; i < per_thread; ++i) out.push_back(c.mono_ns());
            });
        for (auto& t : readers) t.join();
    }
    std::vector<std::int64_t> all;
    for (const auto& out : seen) {
        for (std::size_t i = 1; i < out.size(); ++i) REQUIRE(out[i] > out[i - 1]);
        all.insert(all.end(), out.begin(), out.end());
    }
    std::sort(all.begin(), all.end());
    CHECK(std::adjacent_find(all.begin(), all.end()) == all.end());  // no stamp twice
    const std::int64_t before = c.mono_ns();
    c.advance_s(1.0);  // a pacing step: time moves on by at least the step
    CHECK(c.mono_ns() >= before);
    CHECK(c.mono_ns() >= 11'000'000'000);  // 10 s + the step: what ran on between steps is taken into it
}
