#pragma once
// One daemon of the simulated lab per fuzzing process, idle and deliberately never destroyed
// (its threads outlive the inputs), with its files in this run's own directory: a ring left in
// /dev/shm would outlive the run.
#include <unistd.h>

#include <filesystem>
#include <string>

#include "daemon/lab_daemon.hpp"

namespace manikind::fuzz {

inline LabDaemon& idle_daemon(const std::string& target, const std::string& log_level = "error") {
    static LabDaemon* daemon = [&] {
        namespace fs = std::filesystem;
        const fs::path dir = fs::temp_directory_path() / ("manikind-" + target + "-" + std::to_string(::getpid()));
        fs::create_directories(dir);
        auto config = config::default_config();
        config.database = dir / "fuzz.db";
        config.simulation.runtime_dir = (dir / "sim").string();
        config.log_level = log_level;
        config.recorder_crash_ring_dir = dir.string();
        return new LabDaemon(DaemonOptions{config, true, 1.0});
    }();
    return *daemon;
}

}  // namespace manikind::fuzz
