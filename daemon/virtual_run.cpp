#include "daemon/virtual_run.hpp"

#include "base/user_error.hpp"
#include "daemon/lab_daemon.hpp"

namespace manikind {

VirtualRun run_virtual_campaign(const config::Config& config, const CampaignPlan& plan,
                                const std::function<void(const std::string&)>& on_trial) {
    LabDaemon daemon({config, true, 1.0});
    if (const auto why = daemon.start_campaign(plan); !why.empty()) throw UserError(why);
    daemon.run_virtual(on_trial);
    return {daemon.database_path(), daemon.status_json()["time_s"].get<double>(), daemon.take_computed_campaign()};
}

}  // namespace manikind
