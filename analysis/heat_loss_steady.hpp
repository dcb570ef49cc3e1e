#pragma once
// The clothing standards' stop rule (issue 64): a test is steady when the manikin's whole-body
// heat loss is steady, not only its skin temperature. ASTM F1291's steady state as commonly
// summarised: heat loss within ±3 % and mean skin temperature within ±0.1 °C over 30 min; the
// standards' texts are not public, so the figures here are configurable and docs/clothing.md
// ("The stop rule") says where they come from. Judged as a trend, not a range: the least-squares
// slope of the area-weighted heat loss times the window, against the window's mean (a range of
// noisy samples grows with the noise and says little about a slow approach). The daemon stops a
// clothing trial on it and `manikin clothing` applies the same rule to the recording.
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

namespace manikind::analysis {

struct HeatLossRule {
    double window_s = 1800.0;             // 30 min
    double max_drift_fraction = 0.03;     // the heat loss's trend over the window, of its mean
    double max_mean_skin_drift_c = 0.1;   // the mean skin temperature's trend over the window
};

struct HeatLossVerdict {
    bool observed = false;                // samples cover the window
    double mean_w_m2 = 0.0;               // area-weighted, over the window
    double drift_fraction = 0.0;          // |slope| x window / |mean|
    double mean_skin_drift_c = 0.0;       // |slope| x window
    bool steady = false;
    std::string failing;                  // why not, in words (empty when steady)
};

// Judges samples (t, whole-body heat loss, mean skin) already limited to the window.
HeatLossVerdict judge_heat_loss(const std::vector<double>& t_s, const std::vector<double>& heat_loss_w_m2,
                                const std::vector<double>& mean_skin_c, const HeatLossRule& rule);

// The daemon's running window: one sample per tick, the oldest dropped as the window moves.
class HeatLossWindow {
public:
    void push(std::int64_t t_ns, double heat_loss_w_m2, double mean_skin_c);
    void clear() { samples_.clear(); }
    // The window ending at `now_ns`; `since_ns` is when sampling began (the window is observed
    // once that is a whole window ago).
    HeatLossVerdict judge(const HeatLossRule& rule, std::int64_t now_ns, std::int64_t since_ns);

private:
    struct Sample {
        std::int64_t t_ns;
        double q, skin;
    };
    std::deque<Sample> samples_;
};

}  // namespace manikind::analysis
