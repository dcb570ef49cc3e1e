#pragma once
// The console's parity plot: for each analysed case, the baseline twin's whole-body heat flux at
// the case's recorded steady-window conditions against the measured one with its 95 % CI.
#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"

namespace manikind {

// [{"case", "twin_w_m2", "measured_w_m2", "U_w_m2"}...]; cases without recorded air
// temperature or humidity are left out (the twin needs them).
nlohmann::json twin_parity_json(const analysis::CampaignResult& result);

}  // namespace manikind
