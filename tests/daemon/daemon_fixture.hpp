#pragma once
// A LabDaemon on the simulated lab and the virtual clock, with its database in a fresh folder.
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <memory>

#include <catch2/catch.hpp>

#include "daemon/campaign_plan.hpp"
#include "daemon/lab_daemon.hpp"

namespace manikind::test {

class DaemonFixture {
public:
    explicit DaemonFixture(std::function<void(config::Config&)> tweak = {}) {
        static std::atomic<int> serial{0};
        dir_ = std::filesystem::temp_directory_path() /
               ("manikind-test-daemon-" + std::to_string(::getpid()) + "-" + std::to_string(serial++));
        std::filesystem::create_directories(dir_);
        config::Config c = config::default_config();
        c.database = dir_ / "test.db";
        c.simulation.runtime_dir = (dir_ / "sim").string();
        c.log_level = "error";
        if (tweak) tweak(c);
        daemon_ = std::make_unique<LabDaemon>(DaemonOptions{c, true, 1.0});
    }
    ~DaemonFixture() {
        daemon_.reset();
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }
    LabDaemon& daemon() { return *daemon_; }
    // Runs a one-trial plan on the virtual clock to its end: its one trial must be done.
    recorder::TrialRow run_one_done_trial(const CampaignPlan& plan) {
        REQUIRE(daemon_->start_campaign(plan).empty());
        daemon_->run_virtual();
        const auto trials = daemon_->db().trials(*daemon_->db().find_campaign(plan.name));
        REQUIRE(trials.size() == 1);
        CHECK(trials[0].state == "done");
        return trials[0];
    }
    const std::filesystem::path& dir() const { return dir_; }

private:
    std::filesystem::path dir_;
    std::unique_ptr<LabDaemon> daemon_;
};

// One dry case, one replicate, a short trial: a whole campaign in a few virtual hours.
inline CampaignPlan quick_plan(const std::string& name, double trial_min = 35.0) {
    CampaignPlan p;
    p.name = name;
    p.replicates = 1;
    p.trial_duration_s = trial_min * 60.0;
    p.cases.push_back({1, 35.0, 27.0, 35.0, true, 300.0, std::nullopt, std::nullopt, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});
    return p;
}

}  // namespace manikind::test
