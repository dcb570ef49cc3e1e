#pragma once
// From the recorder's database to the interchange format (analysis::Campaign): each finished
// trial's samples from the manikin's start to the trial's end, binned on a 5-s grid (Text S3.2
// samples every 5 s), good samples only. Air temperature and humidity are the mean of the EE181
// probes, wall temperature the mean of the thermocouples, air speed the WindSonic's.
#include <filesystem>
#include <string>

#include "analysis/recording.hpp"
#include "store/database.hpp"

namespace manikind {

// Throws UserError when the campaign is unknown or has no finished trial (with `include_running`:
// no finished or running one). `include_running`: a trial still acquiring is exported too, from the
// manikin's start to its last committed reading, marked `partial` (an export taken mid-campaign).
analysis::Campaign campaign_from_database(recorder::Database& db, const std::string& campaign_name,
                                          double sample_period_s = 5.0, bool include_running = false);

// A case's number as the export names it: the plan's id, else its position + 1 (also when the
// stored conditions are not a JSON object).
int case_number_of(const recorder::CaseRow& c);
// The export's id of a trial: "c01-r2".
std::string exported_trial_id(int case_number, std::int64_t replicate);

// `manikin export`: writes campaign.json and trials/*.csv into `folder`.
void export_campaign(recorder::Database& db, const std::string& campaign_name, const std::filesystem::path& folder);

}  // namespace manikind
