#pragma once
// `manikin reconcile --power`'s progress on stderr (docs/reconcile.md, "Detection limits"): a bar
// with the share done and the time left where a person watches (a terminal), a plain line now and
// then otherwise (a log). Nothing on stdout: `--json` stays one document.
#include <chrono>
#include <cstdio>
#include <optional>
#include <string>

#include "analysis/reconcile/reconcile.hpp"

namespace manikind::cli {

// "1 min 20 s", "45 s", "2 h 05 min": a time left, rounded to what a person reads.
std::string format_time_left(double seconds);

// One progress line: the share of the expected drawn campaigns done, the terms settled, and the
// time left at `seconds_per_campaign` (none: not yet known). `bar`: a bar of `width` cells first.
std::string format_power_progress(const analysis::reconcile::PowerProgress& p, std::optional<double> seconds_per_campaign,
                                  bool bar, int width = 30);

class PowerProgressMeter {
public:
    // `terminal`: redraw one bar in place (at most every 0.2 s); otherwise a line every `every_s`.
    PowerProgressMeter(std::FILE* out, bool terminal, double every_s = 10.0);
    void update(const analysis::reconcile::PowerProgress& p);
    // Ends the bar's line (a terminal); nothing otherwise.
    void finish();

private:
    std::FILE* out_;
    bool terminal_;
    double every_s_;
    // The rate is measured from the first campaign reconciled (what comes before it, reading the
    // campaign and the nulls, is not the planner's pace).
    std::optional<std::chrono::steady_clock::time_point> first_, last_;
    int first_done_ = 0;
    bool drawn_ = false;
};

}  // namespace manikind::cli
