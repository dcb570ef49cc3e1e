#pragma once
// The operator console: HTTP and WebSocket in the daemon (Boost.Beast), on a loopback address
// only. The page's files (web/) are compiled into the program: nothing is fetched from outside.
//   GET  /                      the console page (web/index.html, console.js, console.css)
//   GET  /api/status /api/live /api/zones /api/history /api/alarms /api/results[?campaign=]
//   GET  /metrics               Prometheus text format (docs/daemon.md, "Metrics")
//   POST /api/command           a control-API request ({"cmd":..., "token":...}): the same code
//                               path, token and safety limits as the Unix socket
//   GET  /ws                    WebSocket: an update (status + live) on every new sample (bursts
//                               coalesced over 20 ms), and at least every second
// Reading needs no token; anything that changes state needs the API token. Requests whose Host
// is not this loopback address (DNS rebinding) or whose Origin is another site are refused.
// Clients follow the control API's rules: a cap, an idle timeout, and a bound on unsent updates;
// at the cap an HTTP client makes room before an established WebSocket (the operator's live
// view), new connections per address are rate-limited (503 past it), oversized headers get 431.
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "daemon/control_api.hpp"
#include "daemon/lab_daemon.hpp"

namespace manikind {

// The page sends nothing but pings and close: a bigger WebSocket message is refused.
inline constexpr std::size_t kConsoleWsMaxMessageBytes = 4096;
inline constexpr std::size_t kConsoleHeaderLimitBytes = 16 * 1024;

struct WebOptions {
    std::string host = "127.0.0.1";      // loopback only: 127.0.0.1, ::1 or localhost
    int port = 8470;                     // 0: an ephemeral port (see WebServer::port())
    std::size_t max_clients = 32;        // a newcomer takes an HTTP client's place, a WebSocket's last
    // New connections per client address: a token bucket (this rate, this burst); past it, 503.
    double new_connections_per_s_per_ip = 50.0;
    double new_connection_burst = 100.0;
    double idle_timeout_s = 120.0;       // HTTP keep-alive and request read; WebSocket pings
    std::size_t max_unsent_bytes = 4 * 1024 * 1024;  // a WebSocket client this far behind is dropped
    double history_s = 24 * 3600.0;      // chamber history kept for the page's charts (spans: 1 h, trial, campaign)
};

// "127.0.0.1:8470" -> host, port. Throws UserError when the host is not a loopback address.
WebOptions parse_listen(const std::string& listen, const std::string& where);

class WebServer {
public:
    WebServer(LabDaemon& daemon, ControlOptions api, WebOptions options);
    ~WebServer();
    void start();  // throws UserError when it cannot listen
    void stop();
    int port() const;
    // Where it listens, as a browser is to be pointed at it: "http://127.0.0.2:8470/".
    std::string url() const;
    bool shutdown_requested() const;
    // The chamber history before start() read from the database and merged (for tests); false
    // when `within` passed first.
    bool wait_history_seeded(std::chrono::milliseconds within);
    // One request's bytes parsed with the server's own limits and answered as the server
    // answers it: the response's bytes, or "" where the server would close without a reply. For
    // the fuzz target and tests, on a server that is not started (the server thread owns its state).
    std::string answer_raw(const std::string& request_bytes);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// One file of the page, compiled in (cmake/web_assets.cpp.in).
struct WebAsset {
    const char* path;          // "/console.js"
    const char* content_type;
    const char* body;
    std::size_t size;
};
const WebAsset* find_web_asset(const std::string& path);

}  // namespace manikind
