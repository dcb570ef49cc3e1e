#include "cli/power_progress.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/core.h>

namespace manikind::cli {

std::string format_time_left(double seconds) {
    const long s = std::lround(std::max(0.0, seconds));
    if (s < 60) return fmt::format("{} s", s);
    if (s < 3600) return fmt::format("{} min {:02} s", s / 60, s % 60);
    return fmt::format("{} h {:02} min", s / 3600, (s % 3600) / 60);
}

std::string format_power_progress(const analysis::reconcile::PowerProgress& p, std::optional<double> seconds_per_campaign,
                                  bool bar, int width) {
    const int expected = std::max(1, std::max(p.campaigns_expected, p.campaigns_done));
    const double share = std::clamp(static_cast<double>(p.campaigns_done) / expected, 0.0, 1.0);
    std::string out;
    if (bar) {
        const int filled = static_cast<int>(std::floor(share * width));
        out = "[" + std::string(static_cast<std::size_t>(filled), '#') + std::string(static_cast<std::size_t>(width - filled), '.') + "] ";
    } else {
        out = "power: ";
    }
    out += fmt::format("{:3.0f} %", 100.0 * share);
    // The expected count is an estimate: the values a term takes are found as it goes.
    if (seconds_per_campaign) out += ", about " + format_time_left(*seconds_per_campaign * (expected - p.campaigns_done)) + " left";
    out += fmt::format(" ({} of ~{} drawn campaigns at {} replicates; {} of {} terms settled; last: {})", p.campaigns_done,
                       expected, p.replicates, p.terms_done, p.terms, p.label);
    return out;
}

PowerProgressMeter::PowerProgressMeter(std::FILE* out, bool terminal, double every_s)
    : out_(out), terminal_(terminal), every_s_(every_s) {}

void PowerProgressMeter::update(const analysis::reconcile::PowerProgress& p) {
    const auto now = std::chrono::steady_clock::now();
    if (!first_) {
        first_ = now;
        first_done_ = p.campaigns_done;
    }
    const double since = last_ ? std::chrono::duration<double>(now - *last_).count() : 1e9;
    if (since < (terminal_ ? 0.2 : every_s_)) return;
    last_ = now;
    std::optional<double> rate;
    if (p.campaigns_done > first_done_)
        rate = std::chrono::duration<double>(now - *first_).count() / (p.campaigns_done - first_done_);
    if (terminal_) {
        // \x1b[K clears what a longer line left behind.
        std::fprintf(out_, "\r%s\x1b[K", format_power_progress(p, rate, true).c_str());
        drawn_ = true;
    } else {
        std::fprintf(out_, "%s\n", format_power_progress(p, rate, false).c_str());
    }
    std::fflush(out_);
}

void PowerProgressMeter::finish() {
    if (terminal_ && drawn_) std::fprintf(out_, "\n");
    std::fflush(out_);
}

}  // namespace manikind::cli
