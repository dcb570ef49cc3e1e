#pragma once
// The steady-state rule's building block (Methods: every zone within 0.05 °C over the last
// 30 min): the range (max - min) of one signal over a sliding time window, kept with monotonic
// deques, O(1) amortised per sample, so the daemon can judge 35 zones at every step.
#include <cstdint>
#include <deque>
#include <utility>

namespace manikind::analysis {

// The sliding range (max - min) of one signal over a time window: monotonic deques, O(1) per sample.
class SlidingRange {
public:
    void push(std::int64_t t_ns, double v);
    void evict_before(std::int64_t t_ns);
    double range() const;
    std::int64_t oldest_ns() const { return all_.empty() ? 0 : all_.front(); }
    bool empty() const { return all_.empty(); }
    void clear() { maxq_.clear(), minq_.clear(), all_.clear(); }

private:
    std::deque<std::pair<std::int64_t, double>> maxq_, minq_;
    std::deque<std::int64_t> all_;
};

}  // namespace manikind::analysis
