#pragma once
// Reconcile's inputs from the analysis pipeline's case results: per case the steady-window
// conditions, per zone the replicate mean, its U and k, and the zone map's geometry.
#include <string>
#include <vector>

#include "analysis/analyze.hpp"
#include "analysis/reconcile/reconcile.hpp"

namespace manikind::analysis::reconcile {

// The replicate-mean of a condition channel (air_temp_c, air_rh_pct, skin_temp_c,
// air_speed_m_s, wall_temp_c); NaN when the case has none.
double case_condition(const CaseResult& c, const std::string& channel);

// Cases without a recorded air temperature or humidity are left out (named in `skipped`).
std::vector<CaseInput> case_inputs_from_results(const CampaignResult& result, const ZoneMap& map,
                                                std::vector<int>* skipped = nullptr);

}  // namespace manikind::analysis::reconcile
