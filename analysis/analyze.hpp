#pragma once
// The analysis pipeline (Text S3, "3.2 Experimental procedure", Eq. S7):
//   per trial:  steady-state window, zone time-means of heat flux and skin temperature;
//   per case:   replicate means, Type A (scatter of the replicates), Type B (instrument
//               specs), area weighting to regions and whole body, u_C, nu_eff, k, U.
// Results are plain structs so a recorder can store them (SQLite) as well as print them.
#include <filesystem>
#include <map>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/recording.hpp"
#include "analysis/steady_state.hpp"
#include "analysis/uncertainty.hpp"

namespace manikind::analysis {

// How the zone heat-flux sensors' Type B errors combine in an area-weighted mean
// (docs/analysis.md, "Type B of a region").
enum class TypeBCorrelation {
    correlated,    // r = 1 between zones: u_B(region) = sum w_z u_B(z) (default, conservative)
    uncorrelated,  // r = 0: u_B(region) = sqrt(sum (w_z u_B(z))²)
};
const char* to_string(TypeBCorrelation c);

struct AnalysisOptions {
    SteadyStateOptions steady;
    bool include_unsteady = false;   // analyse trials that never settled (flagged either way)
    TypeBCorrelation type_b_correlation = TypeBCorrelation::correlated;
    double confidence = 0.95;        // the paper's 95 % (Eq. S7)
    // k of U = k u_C: GUM Welch-Satterthwaite (default) or the paper's t_{n-1} (Text S3).
    Coverage coverage = Coverage::welch_satterthwaite;
    // Relative uncertainty Δu/u of every Type B standard uncertainty; its dof is
    // 0.5 (Δu/u)^-2 (GUM G.4.2). 0 = limits exactly known, infinite dof (default).
    double type_b_relative_uncertainty = 0.0;

    CoverageOptions coverage_options() const;
};

// One line of an uncertainty budget. Shares add up to 1 over a budget: the Type A line
// takes u_A²/u_C², the Type B lines split u_B²/u_C² between zones (or regions).
struct BudgetLine {
    std::string source;              // "Type A: replicate scatter", "Type B: heat flux, head"
    char type = 'A';                 // 'A' or 'B'
    double u_w_m2 = 0.0;             // the contribution to u_C (for B lines: w x u_B of the part)
    double dof = kInfiniteDof;
    double share = 0.0;              // fraction of u_C²
    std::string part;                // for B lines: the region (whole body) or zone (region)
};

struct AreaResult {                  // a region or the whole body
    std::string name;                // region name, or "whole_body"
    double area_m2 = 0.0;
    Estimate q;                      // q.value in W/m², positive = heat lost by the manikin
    std::vector<BudgetLine> budget;
};

struct ZoneResult {
    int zone = 0;
    std::string name;
    std::string region;
    double area_m2 = 0.0;
    Estimate q;
    double skin_temp_c = 0.0;        // replicate mean of the window-mean skin temperature
};

struct TrialResult {
    std::string id;
    int replicate = 0;
    std::size_t rows = 0;
    SteadyStateResult steady;
    bool included = false;           // used for the case's results
    std::string exclusion_reason;    // empty when included
    // Means over the steady window (NaN when the trial has none).
    double whole_body_q_w_m2 = 0.0;
    std::vector<double> zone_q_w_m2;
    std::vector<double> zone_skin_temp_c;
    double air_temp_c = 0.0;
    double air_rh_pct = 0.0;
    double air_speed_m_s = 0.0;      // NaN when not recorded
    double wall_temp_c = 0.0;        // NaN when not recorded
    double mean_skin_temp_c = 0.0;   // area-weighted
};

struct ConditionEstimate {
    std::string channel;             // air_temp_c, air_rh_pct, skin_temp_c, air_speed_m_s, wall_temp_c
    Estimate e;
};

struct CaseResult {
    int case_id = 0;
    int n_replicates = 0;            // trials used
    bool type_a_estimable = false;   // n_replicates >= 2; otherwise every u_A is NaN (absent)
    std::vector<ConditionEstimate> conditions;
    std::optional<double> wettedness;
    std::optional<double> skin_setpoint_c;
    LocalRoom local;                 // the room the campaign stated for this case, per zone (empty: uniform)
    AreaResult whole_body;
    std::vector<AreaResult> regions;
    std::vector<ZoneResult> zones;
    std::vector<TrialResult> trials; // all trials of the case, used or not
    std::vector<std::string> warnings;
};

struct CampaignResult {
    std::string campaign;
    AnalysisOptions options;
    std::vector<CaseResult> cases;           // cases with at least one usable trial
    std::vector<CaseResult> unanalysed_cases;// cases whose every trial was excluded
    std::vector<std::string> warnings;       // includes the reader's
};

CampaignResult analyze_campaign(const Campaign& campaign, const AnalysisOptions& options = {});

// The same analysis in its two halves, so a campaign need not be in memory all at once.
// summarize_trial: one trial's steady window and window means; the result keeps no samples.
TrialResult summarize_trial(const Trial& trial, const ZoneMap& map, const AnalysisOptions& options = {});
// aggregate_trials: everything per case from already summarised trials, `results[i]` being
// `campaign.trials[i]`'s. Reads the campaign's name, zone map, instruments, warnings and
// trial infos, never the trials' samples (they may be empty, as read_campaign_metadata leaves them).
CampaignResult aggregate_trials(const Campaign& campaign, const std::vector<TrialResult>& results,
                                const AnalysisOptions& options = {});

// analyze_campaign(read_campaign(folder, read), options), one trial in memory at a time:
// campaign.json once, then each trial's CSV read, summarised and freed before the next.
// Same result and the same InputError on bad input.
CampaignResult analyze_campaign_streaming(const std::filesystem::path& folder, const ReadOptions& read = {},
                                          const AnalysisOptions& options = {});

// The `manikin analyze --json` contract (docs/formats.md section 2), plus extra fields.
nlohmann::json to_json(const CampaignResult& result);
// Writes exactly `j.dump(indent)`, j being to_json(result) with the keys of `extra` (an
// object) added, but builds the JSON of one case at a time: the whole document of a large
// campaign (14 MB of text for 450 trials) is never in memory. indent >= 0.
void write_json(std::ostream& out, const CampaignResult& result, int indent,
                const nlohmann::json& extra = nlohmann::json::object());
// A readable table: per case, whole body and regions with u_A, u_B, u_C, nu_eff, k, U, the
// trials and their steady windows, and the whole-body uncertainty budget.
std::string format_table(const CampaignResult& result);
// One row per case and whole body / region / zone.
std::string format_csv(const CampaignResult& result);

}  // namespace manikind::analysis
