#pragma once
// The same campaign measured in several labs (an ISO 5725 / ASTM F2370 round robin): for each case
// every lab's whole-body heat flux with its 95 % CI, and across labs the repeatability and
// reproducibility standard deviations of ISO 5725-2 (analysis/interlab.hpp). `manikin archive
// compare` builds it from the archive; this part never touches a database.
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"
#include "analysis/interlab.hpp"

namespace manikind::analysis {

struct LabCampaignResult {
    std::string lab_id;
    CampaignResult result;
};

struct InterlabLabLine {
    std::string lab_id;
    int n = 0;                        // replicates used (the case's included trials)
    double q_w_m2 = 0.0;              // the lab's whole-body result, Q_Exp-WB (replicate mean)
    double expanded_u_w_m2 = 0.0;     // its 95 % half-width (Type A + B, Eq. S7); NaN when not estimable
    double air_temp_c = 0.0;          // the lab's measured enclosure air temperature (replicate mean)
    double air_rh_pct = 0.0;
    std::vector<double> replicates_w_m2;  // each included trial's whole-body flux
    double mandel_h = 0.0, mandel_k = 0.0;  // NaN when the case has no precision estimate
};

struct InterlabCase {
    int case_id = 0;
    std::optional<double> skin_setpoint_c;
    std::optional<double> wettedness;
    std::vector<InterlabLabLine> labs;          // labs with at least one usable trial of the case
    std::optional<PrecisionEstimate> precision;  // needs two labs with two replicates each
    std::string note;                            // why there is no precision estimate, or a disagreement
};

struct InterlabReport {
    std::string campaign;
    std::vector<std::string> labs;   // every lab compared, in the order given
    std::vector<InterlabCase> cases; // by case id
    std::vector<std::string> warnings;
};

// Cases are matched by id; a case whose skin setpoint or wettedness differs between labs is not
// the same level and gets no precision estimate (its note says which lab differs). Labs with a
// single usable replicate of a case are listed but left out of its estimate (ISO 5725-2 needs
// n >= 2 per cell to separate repeatability from the between-lab part).
InterlabReport compare_labs(const std::string& campaign, const std::vector<LabCampaignResult>& labs);

nlohmann::json interlab_to_json(const InterlabReport& report);
std::string interlab_to_text(const InterlabReport& report);

}  // namespace manikind::analysis
