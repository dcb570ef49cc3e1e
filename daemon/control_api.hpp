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
// nothing. Messages longer than max_message_bytes are refused and the connection closed. The
// limits on clients (count, idle time, unread replies) are in ControlOptions; docs/daemon.md.
#include <sys/un.h>

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <memory>

#include <nlohmann/json.hpp>

#include "daemon/control_client.hpp"
#include "daemon/instance_lock.hpp"
#include "daemon/lab_daemon.hpp"

namespace manikind {

struct ControlOptions {
    std::filesystem::path socket_path = "manikind.sock";
    int tcp_port = 0;                    // 0: no TCP listener; else 127.0.0.1:<port>
    std::string token;                   // required for mutating commands
    std::size_t max_message_bytes = 64 * 1024;
    // No client can hold the control path: each is served asynchronously with its own buffers.
    std::size_t max_clients = 64;                      // lowered at start to fit RLIMIT_NOFILE
    double idle_timeout_s = 120.0;                     // a client silent this long is disconnected
    double request_timeout_s = 10.0;                   // a request line must arrive whole within this
    // A request line still incomplete this long after its first byte holds no claim on its place:
    // when the server is full it is the first to go (a finished request's client is kept longer).
    double partial_grace_s = 0.5;
    // Connections one process (SO_PEERCRED pid, Unix socket) may hold; 0: max(4, max_clients / 4).
    // Past it, that process's own least useful connection makes room: it can crowd out only itself.
    std::size_t max_clients_per_peer = 0;
    std::size_t max_unread_reply_bytes = 1024 * 1024;  // replies a client has not read; beyond: dropped
    int listen_backlog = 4096;                         // capped by net.core.somaxconn
};

// Who sent a request: recorded with an abort. The console's abort must also name the campaign
// it aborts ("confirm"), as the operator typed it.
struct RequestOrigin {
    std::string who = "a control-socket client";
    bool abort_needs_confirmation = false;
};

// Handles one request line (no I/O). `shutdown_requested` is set by a valid shutdown.
nlohmann::json handle_request(LabDaemon& daemon, const ControlOptions& options, const std::string& line,
                              bool& shutdown_requested, const RequestOrigin& origin = {});

// What the server has done with its clients (status and tests).
struct ControlServerCounters {
    std::uint64_t accepted = 0;
    std::uint64_t evicted_idle = 0;       // disconnected to make room for a new one (a stale half-written
                                          // request first, then one that never asked, then the longest idle)
    std::uint64_t evicted_peer = 0;       // one process over max_clients_per_peer: its own connection let go
    std::uint64_t refused_full = 0;       // refused: every slot mid-reply or with a fresh half-written request
    std::uint64_t dropped_unread = 0;     // replies piled up unread past max_unread_reply_bytes
    std::uint64_t timed_out = 0;          // idle, or a request not finished within request_timeout_s
    std::uint64_t accept_errors = 0;      // accept failed (e.g. out of file descriptors); retried, never spun
    std::size_t connected = 0;
    std::size_t max_clients = 0;          // the effective cap
    std::size_t max_clients_per_peer = 0; // the effective per-process cap
};

// Serves the control API on one Boost.Asio thread. A client that never reads, writes slowly, or
// just holds a connection open cannot delay anyone else: replies are queued per client and
// written asynchronously, and the limits above drop the client, never block the server.
class ControlServer {
public:
    ControlServer(LabDaemon& daemon, ControlOptions options);
    ~ControlServer();
    // Takes the socket's lock (one daemon per socket), replaces a stale socket only when no one
    // answers on it, and listens. Throws UserError naming the path and the holder's PID.
    void start();
    // The daemon takes the socket's lock before anything else (database, token file), so a second
    // daemon is refused before it touches either; start() then uses this lock.
    void adopt_socket_lock(InstanceLock lock);
    void stop();
    bool shutdown_requested() const;
    int tcp_port() const;
    // Seconds since the server's own timer last ran: the watchdog is fed only while it is small.
    double seconds_since_heartbeat() const;
    ControlServerCounters counters() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Token handling: when the config sets none, the daemon makes one and writes it beside the socket
// (<socket>.token, mode 0600) for local clients of the same user. The file is created with
// O_EXCL|O_NOFOLLOW: never written through a symlink; an existing file is replaced only when it is
// the daemon user's own and no one else can read it, else the daemon refuses to start, saying why.
// A configured token must be strong (config::token_problem).
std::string load_or_create_token(const std::string& configured, const std::filesystem::path& socket_path);

}  // namespace manikind
