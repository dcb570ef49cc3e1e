#pragma once
// A campaign to run: cases (chamber setpoints, skin setpoint, wet or dry) x replicates, from a
// TOML file or the built-in Table S3 list. Every setpoint is checked against the configured
// safety limits before anything starts; an error names the file, line and key.
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/recording.hpp"
#include "daemon/config.hpp"

namespace manikind {

// A change of the chamber's setpoints during a physiological trial ([[cases.model.phases]]): the
// protocol's step from one climate to another, `after_s` from the model's start.
struct ChamberPhase {
    double after_s = 0.0;
    double chamber_temp_c = 0.0;
    double chamber_rh_pct = 0.0;
};

// A physiological trial (control = "physiological", [cases.model]): a thermoregulation model
// decides every zone's skin setpoint and sweat rate from the manikin's measured losses
// (docs/thermoregulation.md, "The manikin in the loop").
struct PhysiologicalModel {
    std::string name = "stolwijk-2026";
    double metabolic_met = 1.5;
    double duration_s = 7200.0;
    std::vector<ChamberPhase> phases;
};

// Comfort mode's equation t_sk = a - b q (daemon/comfort_loop.hpp has the source of the defaults).
struct ComfortEquation {
    double a_c = 36.4;          // skin temperature at no heat loss, °C
    double b_c_m2_w = 0.054;    // how much cooler per W/m² lost
    double skin_c(double q_w_m2) const { return a_c - b_c_m2_w * q_w_m2; }
};

struct PlannedCase {
    int id = 0;
    double chamber_temp_c = 0.0;
    double chamber_rh_pct = 0.0;
    double skin_setpoint_c = 35.0;
    bool wet = false;
    double sweat_rate_g_m2_h = 0.0;   // wet cases: the manikin's sweat supply
    // What the enclosure air must reach before the manikin starts (issue 31). The sealed
    // enclosure does not sit at the chamber's setpoint: Table S3 measured it up to 1.6 °C and
    // (wet) 19 % RH away. Default: Table S3's measured T_air and RH_air for the same chamber
    // setpoints (within 0.5 °C, 1 %), else the setpoints themselves (enclosure_target()).
    std::optional<double> enclosure_temp_c;
    std::optional<double> enclosure_rh_pct;
    // Clothing tests (docs/clothing.md): what the manikin wears (an id of CampaignPlan::ensembles
    // or "nude") and the test ("insulation" or "evaporative"); both empty for other campaigns.
    std::string ensemble;
    std::string test;
    // Set for control = "physiological": skin_setpoint_c, wet and the sweat rate are then the model's.
    std::optional<PhysiologicalModel> model;
    // Set for control = "constant-heat-flux" (issue 65): every zone's heating fixed at this flux,
    // W/m², its skin temperature measured; `heat_flux_by_region_w_m2` overrides it per zone-map
    // region. skin_setpoint_c is then not a setpoint.
    std::optional<double> heat_flux_w_m2;
    std::map<std::string, double> heat_flux_by_region_w_m2;
    // Set for control = "comfort" (issue 65): each zone's skin from its own loss, t_sk = a - b q.
    std::optional<ComfortEquation> comfort;
    // [[cases.local]] (issue 65): the room the case's trials meet where it is not uniform, per zone of
    // the andi35 map (empty: uniform, or the simulated lab's own [[simulation.local]]).
    analysis::LocalRoom local;
};



struct EnclosureTarget {
    double air_c = 0.0;
    double rh_pct = 0.0;
};
// The case's enclosure target: as given, else Table S3's measured enclosure for the same chamber
// setpoints, else the setpoints.
EnclosureTarget enclosure_target(const PlannedCase& c);

struct CampaignPlan {
    std::string name;
    int replicates = 3;
    double trial_duration_s = 4500.0;       // Methods: 75 min
    double settle_window_s = 600.0;         // enclosure stable when its air varies < settle_band_c for this long
    double settle_band_c = 0.3;
    // Settled: the enclosure's air within settle_tolerance_c of the case's enclosure_temp_c and
    // its RH within settle_tolerance_rh_pct of enclosure_rh_pct, continuously, and varying less
    // than settle_band_c, over settle_window_s. Table S3's enclosure values carry ±0.2 °C and
    // ±1.5-2.3 % (their u); the tolerances leave room for a replicate's own scatter.
    double settle_tolerance_c = 0.5;
    double settle_tolerance_rh_pct = 5.0;
    // Past this the daemon raises an alarm and holds (never starts the manikin off target).
    double settle_timeout_s = 3.0 * 3600.0;
    // While acquiring: the enclosure off its target (the settling tolerances) for longer than this
    // is an excursion: the trial is flagged, an alarm raised, and the steady-state window starts
    // again when the enclosure is back, so the final window never holds an excursion.
    double excursion_limit_s = 120.0;
    double acquire_timeout_s = 4.0 * 3600.0;
    std::vector<PlannedCase> cases;
    std::map<std::string, analysis::Ensemble> ensembles;  // campaign TOML `[ensembles.<id>]`: what cases may wear
    std::map<std::string, std::string> standards;          // campaign TOML `[standards]`: test -> standard with edition
};

// What the database stores of a plan (campaigns.definition_json, cases.conditions_json): what a
// continued campaign is compared with.
nlohmann::json campaign_definition_json(const CampaignPlan& plan);
nlohmann::json case_conditions_json(const PlannedCase& c);

// How `plan` differs from a campaign stored as `definition` and `case_conditions` (in position
// order), one readable line per difference; empty when it is the same plan.
std::vector<std::string> plan_differences(const CampaignPlan& plan, const nlohmann::json& definition,
                                          const std::vector<nlohmann::json>& case_conditions);

// The paper's 15 validation cases (Table S3) x 3 replicates.
CampaignPlan table_s3_plan(const std::string& name);

// Why the plan's names and texts cannot be stored (base/text.hpp's one rule: the campaign's name,
// each ensemble's id and description, each case's ensemble and test), or empty. LabDaemon checks
// every plan with it, whatever brought it (API, console, file, built-in), before it is stored.
std::string plan_text_problem(const CampaignPlan& plan);

// `text` is the TOML; `source` names it in messages. A key the parser does not know is an error
// ("file:line:column: key: unknown key (did you mean '...'?)"): the daemon refuses such a plan. "builtin:table-s3" as a file name gives the
// Table S3 plan. Throws UserError.
CampaignPlan parse_campaign_plan(const std::string& text, const std::string& source);
CampaignPlan load_campaign_plan(const std::string& file_or_builtin);

// Empty when every case is inside the limits, else the first violation with the limit named.
// Levenshtein distance, for "did you mean" suggestions.
std::size_t edit_distance(std::string_view a, std::string_view b);

std::string check_plan_against_limits(const CampaignPlan& plan, const config::SafetyLimits& limits);
// Every case against what the configured manikin can do, before any heating (issue 31): the
// baseline twin's steady zone losses at the case's air, humidity and skin setpoint, in still
// air, against the heaters' rating ([devices.manikin] max_heater_power_w_m2) and the heater
// power limit ([safety]). Empty when every case fits; else the first case that does not, why,
// and by how much.
std::string check_plan_against_devices(const CampaignPlan& plan, const config::Config& config);

}  // namespace manikind
