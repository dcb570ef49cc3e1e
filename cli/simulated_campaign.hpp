#pragma once
// A simulated campaign as the interchange format's in-memory Campaign, ready for
// analysis::write_campaign or analysis::analyze_campaign.
#include <string>
#include <vector>

#include "analysis/recording.hpp"
#include "sim/campaign/campaign_generator.hpp"

namespace manikind {

// Generates the trials for `cases` on the ANDI 35-zone map and packages them as a Campaign.
// Throws std::invalid_argument for bad generator options.
analysis::Campaign simulate_campaign(const std::string& name, const std::vector<sim::CampaignCase>& cases,
                                     const sim::GeneratorOptions& options, int* unsteady_trials = nullptr);

}  // namespace manikind
