// The sliding range behind the steady-state rule, against a brute-force max - min of the window.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include "analysis/sliding_range.hpp"

using manikind::analysis::SlidingRange;

TEST_CASE("sliding range: max - min over the window equals a brute-force scan at every step", "[steady]") {
    SlidingRange r;
    CHECK(r.empty());
    CHECK(std::isnan(r.range()));
    std::mt19937_64 rng(7);
    std::normal_distribution<double> noise(0.0, 0.02);
    std::vector<std::pair<std::int64_t, double>> kept;
    const std::int64_t window_ns = 30 * 60 * 1'000'000'000LL;
    double drift_c = 35.0;
    for (std::int64_t i = 0; i < 2000; ++i) {
        const std::int64_t t = i * 5'000'000'000LL;  // a reading every 5 s
        drift_c += i < 1000 ? 0.001 : 0.0;           // heating, then level
        const double v = drift_c + noise(rng);
        r.push(t, v);
        r.evict_before(t - window_ns);
        kept.emplace_back(t, v);
        std::erase_if(kept, [&](const auto& p) { return p.first < t - window_ns; });
        const auto [lo, hi] = std::minmax_element(kept.begin(), kept.end(),
                                                  [](const auto& a, const auto& b) { return a.second < b.second; });
        REQUIRE(r.range() == hi->second - lo->second);
        REQUIRE(r.oldest_ns() == kept.front().first);
    }
    r.clear();
    CHECK(r.empty());
}
