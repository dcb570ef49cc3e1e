// libFuzzer target for one control-API message (daemon/control_api.hpp): the input as a
// request line to handle_request, on an idle daemon of the simulated lab that is never run.
// Every reply must be a JSON object with "ok"; nothing may escape (errors are replies).
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/control_api.hpp"
#include "fuzz/idle_daemon.hpp"
#include "fuzz/fuzz_check.hpp"

namespace {

constexpr const char* kToken = "fuzz-token-7Hq2Lx9Vb4Rk";

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
    const auto reply = manikind::handle_request(manikind::fuzz::idle_daemon("fuzz-control"), options, line, shutdown_requested);
    FUZZ_CHECK(reply.is_object() && reply.contains("ok") && reply["ok"].is_boolean());
    FUZZ_CHECK(reply["ok"] == true || reply.contains("error"));
    return 0;
}
