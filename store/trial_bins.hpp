#pragma once
// A trial's readings on the exports' grid (Text S3.2 samples every 5 s): row i covers
// (t_i - period, t_i] with t_i = i x period after the manikin's start. ChannelBinner is what
// CampaignReader bins a channel with when it reads a trial back from the database; TrialBins does
// the same as the daemon records, so a campaign computed on the virtual clock need not read its
// 9 M readings back (issue 36). Both feed every channel's readings through the same arithmetic in
// the same order (each channel's readings come in time order), so the two agree bit for bit.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <vector>

#include "analysis/recording.hpp"
#include "store/database.hpp"

namespace manikind::recorder {

struct BinnedChannel {
    std::vector<double> value;
    std::vector<std::uint8_t> quality;  // analysis::kNoSample where no sample fell in the row
};

// One channel's readings as they come. The value of a row is the mean of its good readings (the
// reading itself when one fell in it); when none was good, the last reading's value and quality
// (a "good" NaN is a lost reading: quality 3). Rows beyond `max_rows` are not kept.
class ChannelBinner {
public:
    ChannelBinner(std::int64_t t0_ns, double period_s, std::size_t max_rows = std::numeric_limits<std::size_t>::max())
        : t0_ns_(t0_ns), period_s_(period_s), max_rows_(max_rows) {}

    void add(const SampleRow& r) {
        any_ = true;
        const double t = static_cast<double>(r.mono_ns - t0_ns_) * 1e-9;
        if (t < -period_s_) return;
        const auto i = static_cast<long>(std::ceil(t / period_s_ - 1e-9));
        if (i < 0 || static_cast<std::size_t>(i) >= max_rows_) return;
        const auto k = static_cast<std::size_t>(i);
        if (k >= sum_.size()) grow(k + 1);
        if (r.quality == 0 && std::isfinite(r.value)) {
            sum_[k] += r.value;
            ++good_[k];
        } else if (good_[k] == 0) {
            value_[k] = r.value;
            quality_[k] = r.quality == 0 ? std::uint8_t{3} : r.quality;
        }
    }
    // A reading of the channel that lies before the grid: it counts as "recorded" only.
    void mark_seen() { any_ = true; }
    bool any_sample() const { return any_; }

    // The first `n` rows.
    BinnedChannel finish(std::size_t n) const {
        BinnedChannel out{std::vector<double>(n, std::numeric_limits<double>::quiet_NaN()),
                          std::vector<std::uint8_t>(n, analysis::kNoSample)};
        for (std::size_t k = 0; k < std::min(n, sum_.size()); ++k) {
            if (good_[k] > 0) {
                out.value[k] = good_[k] == 1 ? sum_[k] : sum_[k] / good_[k];
                out.quality[k] = 0;
            } else {
                out.value[k] = value_[k];
                out.quality[k] = quality_[k];
            }
        }
        return out;
    }
    std::size_t rows() const { return sum_.size(); }
    std::size_t bytes() const { return sum_.capacity() * (sizeof(double) * 2 + sizeof(int) + 1); }

private:
    void grow(std::size_t n) {
        sum_.resize(n, 0.0);
        good_.resize(n, 0);
        value_.resize(n, std::numeric_limits<double>::quiet_NaN());
        quality_.resize(n, analysis::kNoSample);
    }
    std::int64_t t0_ns_;
    double period_s_;
    std::size_t max_rows_;
    std::vector<double> sum_;
    std::vector<int> good_;
    std::vector<double> value_;
    std::vector<std::uint8_t> quality_;
    bool any_ = false;
};

// One trial binned as it is recorded: every row offered for the trial goes to add(), in the order
// offered; start() when the manikin starts (the "acquiring" stage, at that event's mono_ns). Rows
// up to one period before the start fall in row 0, so the last period before it is kept until then.
// seal() when no row of the trial can come any more (the next trial began): the bins shrink to
// their results, a value and a quality a row. A second start, or a row after the seal, makes them
// unusable: the reader then reads the trial from the database.
class TrialBins {
public:
    explicit TrialBins(double period_s = 5.0) : period_s_(period_s) {}

    void add(const SampleRow& r);
    void start(std::int64_t t0_mono_ns);
    void seal();
    void invalidate() { valid_ = false; }

    bool usable() const { return valid_ && started_; }
    bool sealed() const { return sealed_; }
    double period_s() const { return period_s_; }
    std::int64_t t0_mono_ns() const { return t0_ns_; }
    std::uint64_t rows() const { return rows_; }  // every row offered, before and after the start
    // Whether any row of the channel came, and its first n grid rows (empty ones as no sample).
    bool any_sample(std::int64_t channel_id) const;
    BinnedChannel binned(std::int64_t channel_id, std::size_t n) const;
    std::size_t bytes() const;

private:
    bool has(std::int64_t channel_id) const {
        return channel_id >= 0 && static_cast<std::size_t>(channel_id) < present_.size() && present_[static_cast<std::size_t>(channel_id)];
    }
    double period_s_;
    bool valid_ = true, started_ = false, sealed_ = false;
    std::int64_t t0_ns_ = 0;
    std::uint64_t rows_ = 0;
    std::deque<SampleRow> before_;       // rows of the last two periods before the start
    std::vector<bool> present_;          // by channel id (SQLite rowids from 1: small): a row came
    std::vector<ChannelBinner> by_id_;   // by channel id, from the start until the seal
    std::vector<BinnedChannel> sealed_rows_;  // by channel id, after the seal
};

}  // namespace manikind::recorder
