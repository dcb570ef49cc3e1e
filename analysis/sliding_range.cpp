#include "analysis/sliding_range.hpp"

#include <cmath>

namespace manikind::analysis {

void SlidingRange::push(std::int64_t t, double v) {
    while (!maxq_.empty() && maxq_.back().second <= v) maxq_.pop_back();
    maxq_.emplace_back(t, v);
    while (!minq_.empty() && minq_.back().second >= v) minq_.pop_back();
    minq_.emplace_back(t, v);
    all_.push_back(t);
}

void SlidingRange::evict_before(std::int64_t t) {
    while (!maxq_.empty() && maxq_.front().first < t) maxq_.pop_front();
    while (!minq_.empty() && minq_.front().first < t) minq_.pop_front();
    while (!all_.empty() && all_.front() < t) all_.pop_front();
}

double SlidingRange::range() const {
    if (maxq_.empty()) return std::nan("");
    return maxq_.front().second - minq_.front().second;
}

}  // namespace manikind::analysis
