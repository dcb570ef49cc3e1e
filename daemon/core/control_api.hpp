#pragma once
// The daemon's control API: newline-delimited JSON over a Unix socket (mode 0660) and,
// optionally, TCP on 127.0.0.1 only. One request per line, one reply per line:
//   {"cmd":"status"}                                  -> {"ok":true,"status":{...}}
//   {"cmd":"live"} | {"cmd":"results","campaign":"name"}
//   {"cmd":"start_campaign","token":"...","plan_toml":"..."} or "builtin":"table-s3","name":"..."
//   {"cmd":"abort"|"pause"|"resume","token":"..."}
//   {"cmd":"set_chamber","token":"...","chamber_temp_c":35,"chamber_rh_pct":40}
//   {"cmd":"shutdown","token":"..."}
// Mutating commands need the configured token. Errors are {"ok":false,"error":"..."} and change
// nothing. Messages longer than max_message_bytes are refused and the connection closed.
#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "daemon/core/lab_daemon.hpp"

namespace manikind {

struct ControlOptions {
    std::filesystem::path socket_path = "manikind.sock";
    int tcp_port = 0;                    // 0: no TCP listener; else 127.0.0.1:<port>
    std::string token;                   // required for mutating commands
    std::size_t max_message_bytes = 64 * 1024;
};

// Handles one request line (no I/O). `shutdown_requested` is set by a valid shutdown.
nlohmann::json handle_request(LabDaemon& daemon, const ControlOptions& options, const std::string& line,
                              bool& shutdown_requested);

class ControlServer {
public:
    ControlServer(LabDaemon& daemon, ControlOptions options);
    ~ControlServer();
    void start();      // throws UserError when the socket cannot be created
    void stop();
    bool shutdown_requested() const { return shutdown_.load(); }
    int tcp_port() const { return bound_tcp_port_; }

private:
    void serve();
    LabDaemon& daemon_;
    ControlOptions o_;
    int unix_fd_ = -1, tcp_fd_ = -1, wake_[2] = {-1, -1};
    int bound_tcp_port_ = 0;
    std::thread thread_;
    std::atomic<bool> shutdown_{false};
};

// Client side (the `manikin` CLI): sends one request, returns the reply. Throws UserError when
// the daemon is not reachable.
nlohmann::json call_daemon(const std::filesystem::path& socket_path, const nlohmann::json& request);

// Token handling: when the config sets none, the daemon makes one and writes it beside the socket
// (<socket>.token, mode 0600) for local clients of the same user.
std::string load_or_create_token(const std::string& configured, const std::filesystem::path& socket_path);
std::string read_token_file(const std::filesystem::path& socket_path);

}  // namespace manikind
