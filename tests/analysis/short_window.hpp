#pragma once
// The hand-made recordings in tests/data/recordings last 30 s: analyse them with a 20-s window.
#include "analysis/analyze.hpp"

namespace manikind::test {

inline analysis::AnalysisOptions short_window() {
    analysis::AnalysisOptions o;
    o.steady.window_s = 20.0;
    return o;
}

}  // namespace manikind::test
