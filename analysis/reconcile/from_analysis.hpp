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

// Findings about the recording, never physics (issue 61): zones whose heat flux was still
// drifting over a used trial's steady window by more than `limit_w_m2` (|slope| x window, the
// steady-state check's flux measure), grouped by zone. A drift is what a recording cannot
// settle: the twin's steady fluxes are not to be fitted to it.
std::vector<std::string> drift_findings(const CampaignResult& result, const ZoneMap& map, double limit_w_m2 = 2.0);

}  // namespace manikind::analysis::reconcile
