#pragma once
// A whole campaign run through the daemon on the simulated lab, in this process, on the virtual
// clock: `manikin demo`. With config.hpp, campaign_plan.hpp, control_client.hpp and
// simulated_lab.hpp this is the daemon's face to the `manikin` program (docs/architecture.md):
// the CLI sees nothing else of the daemon's insides.
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "analysis/recording.hpp"
#include "daemon/campaign_plan.hpp"
#include "daemon/config.hpp"

namespace manikind {

struct VirtualRun {
    std::filesystem::path database;  // where the daemon recorded (config.database)
    double lab_time_s = 0.0;         // virtual time the campaign took
    // The campaign as the daemon's results read it back from the database when it finished (so it
    // is not read twice); nullptr when it did not finish "done" (its results were not computed).
    std::shared_ptr<const analysis::Campaign> campaign;
};

// Starts `plan` on a daemon built from `config` on the simulated lab (virtual clock) and runs it
// to its end; `on_trial` hears a line per trial. Throws UserError when the plan is refused.
VirtualRun run_virtual_campaign(const config::Config& config, const CampaignPlan& plan,
                                const std::function<void(const std::string&)>& on_trial);

}  // namespace manikind
