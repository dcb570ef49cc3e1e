// libFuzzer target for one control-API message (daemon/control_api.hpp): the input as a
// request line to handle_request, on an idle daemon of the simulated lab that is never run.
// Every reply must be a JSON object with "ok"; nothing may escape (errors are replies).
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/control_api.hpp"
#include "daemon/lab_daemon.hpp"
#include "fuzz/fuzz_check.hpp"

namespace fs = std::filesystem;

namespace {

constexpr const char* kToken = "fuzz-token-7Hq2Lx9Vb4Rk";

// One daemon per process, deliberately never destroyed: its threads outlive the inputs.
manikind::LabDaemon& idle_daemon() {
    static manikind::LabDaemon* daemon = [] {
        const fs::path dir = fs::temp_directory_path() / ("manikind-fuzz-control-" + std::to_string(::getpid()));
        fs::create_directories(dir);
        auto config = manikind::config::default_config();
        config.database = dir / "fuzz.db";
        config.simulation.runtime_dir = (dir / "sim").string();
        config.log_level = "error";
        // Never destroyed, so its recorder never removes its crash ring: keep the ring in this
        // run's own directory, not in /dev/shm where it would outlive the run.
        config.recorder_crash_ring_dir = dir.string();
        return new manikind::LabDaemon(manikind::DaemonOptions{config, true, 1.0});
    }();
    return *daemon;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string line(reinterpret_cast<const char*>(data), size);
    // A campaign accepted here would run for hours of virtual time on the daemon's thread and
    // change every later reply: plans have their own target (fuzz_campaign_plan).
    const auto request = nlohmann::json::parse(line, nullptr, false);
    if (request.is_object() && request.contains("cmd") && request["cmd"] == "start_campaign") return -1;

    manikind::ControlOptions options;
    options.token = kToken;
    options.max_message_bytes = 4096;
    bool shutdown_requested = false;
    const auto reply = manikind::handle_request(idle_daemon(), options, line, shutdown_requested);
    FUZZ_CHECK(reply.is_object() && reply.contains("ok") && reply["ok"].is_boolean());
    FUZZ_CHECK(reply["ok"] == true || reply.contains("error"));
    return 0;
}
