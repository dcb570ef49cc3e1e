#include "store/trial_bins.hpp"

namespace manikind::recorder {

namespace {
// Channel ids are SQLite rowids from 1, one per channel: a vector by id stays small. An id beyond
// this makes the bins unusable rather than the vector huge.
constexpr std::int64_t kMaxChannelId = 1 << 20;
}  // namespace

void TrialBins::add(const SampleRow& r) {
    if (!valid_) return;
    if (sealed_ || r.channel_id < 0 || r.channel_id >= kMaxChannelId) {
        valid_ = false;
        return;
    }
    ++rows_;
    const auto id = static_cast<std::size_t>(r.channel_id);
    if (id >= present_.size()) {
        present_.resize(id + 1, false);
        if (started_) by_id_.resize(id + 1, ChannelBinner(t0_ns_, period_s_));
    }
    present_[id] = true;
    if (started_) {
        by_id_[id].add(r);
        return;
    }
    // Before the start only the last period can reach the grid (ChannelBinner drops t < -period,
    // and the start comes after every row offered before it); older rows only mark the channel.
    before_.push_back(r);
    const std::int64_t keep_after = r.mono_ns - static_cast<std::int64_t>(2 * period_s_ * 1e9);
    while (!before_.empty() && before_.front().mono_ns < keep_after) before_.pop_front();
}

void TrialBins::start(std::int64_t t0_mono_ns) {
    if (started_) {  // the reader takes the last start: these bins are on another grid
        valid_ = false;
        return;
    }
    started_ = true;
    t0_ns_ = t0_mono_ns;
    by_id_.assign(present_.size(), ChannelBinner(t0_ns_, period_s_));
    for (const auto& r : before_) by_id_[static_cast<std::size_t>(r.channel_id)].add(r);
    before_.clear();
    before_.shrink_to_fit();
}

void TrialBins::seal() {
    if (sealed_) return;
    sealed_ = true;
    if (!usable()) {  // nothing of it will be read
        by_id_.clear();
        by_id_.shrink_to_fit();
        before_.clear();
        return;
    }
    sealed_rows_.resize(by_id_.size());
    for (std::size_t id = 0; id < by_id_.size(); ++id)
        if (present_[id]) sealed_rows_[id] = by_id_[id].finish(by_id_[id].rows());
    by_id_.clear();
    by_id_.shrink_to_fit();
}

bool TrialBins::any_sample(std::int64_t channel_id) const { return has(channel_id); }

BinnedChannel TrialBins::binned(std::int64_t channel_id, std::size_t n) const {
    BinnedChannel out{std::vector<double>(n, std::numeric_limits<double>::quiet_NaN()),
                      std::vector<std::uint8_t>(n, analysis::kNoSample)};
    if (!started_ || !has(channel_id)) return out;
    const auto id = static_cast<std::size_t>(channel_id);
    if (!sealed_) return by_id_[id].finish(n);
    const BinnedChannel& s = sealed_rows_[id];
    const std::size_t m = std::min(n, s.value.size());
    std::copy_n(s.value.begin(), m, out.value.begin());
    std::copy_n(s.quality.begin(), m, out.quality.begin());
    return out;
}

std::size_t TrialBins::bytes() const {
    std::size_t b = before_.size() * sizeof(SampleRow) + present_.size() / 8 + by_id_.capacity() * sizeof(ChannelBinner) +
                    sealed_rows_.capacity() * sizeof(BinnedChannel);
    for (const auto& c : by_id_) b += c.bytes();
    for (const auto& s : sealed_rows_) b += s.value.capacity() * sizeof(double) + s.quality.capacity();
    return b;
}

}  // namespace manikind::recorder
