// Issue 60, part 3: control that cannot be locked out. The real daemon and the real CLI
// (build/bin/manikin, the token read from <socket>.token as an operator's CLI reads it) against
// a tokenless attacker: half-written requests holding every place of the control socket, and a
// connection flood on the console while an operator's WebSocket watches. Abort must be answered
// within a second throughout (the requirement), and the live view must stay up.
#include <catch2/catch.hpp>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "daemon/control_api.hpp"
#include "daemon_fixture.hpp"
#include "daemon_process.hpp"

// Outside the unity build: its helpers have the names other files' helpers have.
using namespace manikind;

namespace fs = std::filesystem;
using test::DaemonProcess;
using steady = std::chrono::steady_clock;

namespace {

const std::string lockout_daemon_bin = std::string(MANIKIND_BIN_DIR) + "/manikind";
const std::string lockout_cli_bin = std::string(MANIKIND_BIN_DIR) + "/manikin";

double seconds_since(steady::time_point t0) { return std::chrono::duration<double>(steady::now() - t0).count(); }

fs::path lockout_dir(const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-lockout-{}-{}", name, ::getpid());
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

struct CliRun {
    int exit_code = -1;
    std::string output;
    double seconds = 0;
};

// The CLI as an operator runs it: its own process, the token from <socket>.token (never from the
// test's environment), timed from spawn to exit.
CliRun run_cli(const std::vector<std::string>& args) {
    std::vector<std::string> argv{lockout_cli_bin};
    argv.insert(argv.end(), args.begin(), args.end());
    DaemonProcess::Options options;
    options.env["MANIKIND_TOKEN"] = "";  // empty: the CLI reads <socket>.token
    const auto t0 = steady::now();
    auto cli = DaemonProcess::spawn(argv, options);
    REQUIRE(cli.started());
    const int status = cli.wait();
    CliRun r;
    r.seconds = seconds_since(t0);
    r.output = cli.output();
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

// Stops an attacker thread and joins it when the test leaves its scope, whichever way.
struct StopAndJoin {
    std::atomic<bool>& stop;
    std::thread& t;
    ~StopAndJoin() {
        stop = true;
        t.join();
    }
};

int connect_unix_socket(const fs::path& path) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
        ::close(fd);
        return -1;
    }
    return fd;
}

// A daemon on the simulated lab (real time) running table-s3, no token configured: it writes
// <socket>.token, where the CLI finds it. `console`: also the operator console on an ephemeral port.
struct LiveDaemon {
    fs::path dir, socket;
    DaemonProcess process;
    int console_port = 0;
    static std::vector<std::string> arguments(const fs::path& where, bool with_console) {
        std::vector<std::string> args{lockout_daemon_bin, "--socket", (where / "d.sock").string(), "--database",
                                      (where / "d.db").string(), "--campaign", "builtin:table-s3"};
        if (with_console) args.insert(args.end(), {"--http", "127.0.0.1:0"});
        return args;
    }
    LiveDaemon(const std::string& name, bool console)
        : dir(lockout_dir(name)), socket(dir / "d.sock"), process(DaemonProcess::spawn(arguments(dir, console))) {
        REQUIRE(process.read_until("control socket"));
        if (console) {
            REQUIRE(process.read_until("manikind: console http://127.0.0.1:"));
            const auto& out = process.output();
            const auto at = out.rfind("http://127.0.0.1:") + std::string("http://127.0.0.1:").size();
            console_port = std::stoi(out.substr(at));
        }
        // The campaign starts right after the socket is up: wait for it (bounded).
        for (int i = 0; i < 500; ++i) {
            const auto s = call_daemon(socket, {{"cmd", "status"}}, 5.0);
            if (s["status"]["campaign"].is_string()) return;
        }
        FAIL("the campaign did not start");
    }
    ~LiveDaemon() {
        process.terminate();
        std::error_code ec;
        fs::remove_all(dir, ec);
    }
};

}  // namespace

TEST_CASE("control: one tokenless process holding max_clients half-written requests cannot lock status or abort "
          "out of the CLI",
          "[daemon][api][hardening][lockout]") {
    LiveDaemon d("half-written", false);
    const std::size_t places = ControlOptions{}.max_clients;  // api.max_clients, the default the daemon runs with
    // The attacker: `places` connections, each `{"cmd":"sta` and no newline, any closed one
    // reconnected at once. Bounded: it stops when told, or after 60 s, or a million reconnects.
    std::atomic<bool> stop{false};
    std::atomic<long> reconnects{0};
    std::atomic<bool> holding{false};
    std::thread attacker([&] {
        const std::string half = "{\"cmd\":\"sta";
        auto open_one = [&] {
            const int fd = connect_unix_socket(d.socket);
            if (fd >= 0) (void)::send(fd, half.data(), half.size(), MSG_NOSIGNAL);
            return fd;
        };
        std::vector<pollfd> fds;
        for (std::size_t i = 0; i < places; ++i) fds.push_back({open_one(), POLLIN, 0});
        holding = true;
        const auto end = steady::now() + std::chrono::seconds(60);
        while (!stop && steady::now() < end && reconnects < 1000000) {
            if (::poll(fds.data(), fds.size(), 50) <= 0) {
                for (auto& p : fds)  // a connect refused by a full backlog: try again
                    if (p.fd < 0) p.fd = open_one();
                continue;
            }
            for (auto& p : fds) {
                if (p.fd >= 0 && p.revents == 0) continue;
                char buf[4096];
                if (p.fd >= 0 && ::read(p.fd, buf, sizeof buf) > 0) continue;  // a goodbye; the close follows
                if (p.fd >= 0) ::close(p.fd);
                p.fd = open_one();
                ++reconnects;
            }
        }
        for (auto& p : fds)
            if (p.fd >= 0) ::close(p.fd);
    });
    StopAndJoin join{stop, attacker};
    while (!holding) std::this_thread::yield();

    // The reproduction: six status calls, then the abort, each through the CLI.
    for (int i = 0; i < 6; ++i) {
        const auto r = run_cli({"status", "--socket", d.socket.string(), "--json"});
        INFO("status " << i << ": exit " << r.exit_code << " after " << r.seconds << " s: " << r.output);
        CHECK(r.exit_code == 0);
        CHECK(r.seconds < 1.0);
    }
    const auto aborted = run_cli({"campaign", "abort", "--socket", d.socket.string(), "--reason", "lockout test"});
    INFO("abort: exit " << aborted.exit_code << " after " << aborted.seconds << " s: " << aborted.output);
    CHECK(aborted.exit_code == 0);
    CHECK(aborted.seconds < 1.0);
    stop = true;
    const auto status = call_daemon(d.socket, {{"cmd", "status"}}, 5.0);
    CHECK(status["status"]["campaign"].is_null());
}

namespace {

// An operator's live view: a WebSocket on /ws, every message's arrival time recorded until it is
// told to stop (then `dropped` stays false) or the connection ends (`dropped`).
struct LiveView {
    boost::asio::io_context io;
    boost::beast::websocket::stream<boost::asio::ip::tcp::socket> ws{io};
    std::mutex lock;
    std::condition_variable changed;
    std::vector<steady::time_point> arrivals;
    std::atomic<bool> stopping{false}, dropped{false};
    std::string drop_reason;
    std::thread reader;

    explicit LiveView(int port) {
        const boost::asio::ip::tcp::endpoint at(boost::asio::ip::make_address("127.0.0.1"), static_cast<std::uint16_t>(port));
        ws.next_layer().connect(at);
        ws.handshake(fmt::format("127.0.0.1:{}", port), "/ws");
        reader = std::thread([this] {
            boost::beast::flat_buffer buffer;
            for (;;) {
                boost::beast::error_code ec;
                ws.read(buffer, ec);
                std::lock_guard lk(lock);
                if (ec) {
                    if (!stopping) {
                        dropped = true;
                        drop_reason = ec.message();
                    }
                    changed.notify_all();
                    return;
                }
                buffer.consume(buffer.size());
                arrivals.push_back(steady::now());
                changed.notify_all();
            }
        });
    }
    ~LiveView() {
        stopping = true;
        ::shutdown(ws.next_layer().native_handle(), SHUT_RDWR);
        reader.join();
    }
    std::size_t messages() {
        std::lock_guard lk(lock);
        return arrivals.size();
    }
    // Waits (bounded) until a first message arrived.
    bool wait_first(std::chrono::seconds within) {
        std::unique_lock lk(lock);
        return changed.wait_for(lk, within, [&] { return !arrivals.empty() || dropped; }) && !arrivals.empty();
    }
    // Waits until `until`, or until the view is dropped (then false).
    bool stays_up_until(steady::time_point until) {
        std::unique_lock lk(lock);
        changed.wait_until(lk, until, [&] { return dropped.load(); });
        return !dropped;
    }
};

}  // namespace

TEST_CASE("console: a tokenless connection flood keeps neither the live view off the page nor abort from the CLI",
          "[daemon][console][hardening][lockout][proof]") {
    LiveDaemon d("flood", true);
    LiveView view(d.console_port);
    REQUIRE(view.wait_first(std::chrono::seconds(30)));

    // The flood: new connections as fast as they go, each sending the start of a header and
    // nothing more; at most 256 held, the oldest reset (no TIME_WAIT) to make way. Bounded in
    // time and count; loopback only.
    std::atomic<bool> stop{false};
    std::atomic<long> opened{0};
    std::thread flood([&] {
        const std::string partial = fmt::format("GET /api/status HTTP/1.1\r\nHost: 127.0.0.1:{}\r\n", d.console_port);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(static_cast<std::uint16_t>(d.console_port));
        ::inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
        std::vector<int> held;
        const auto end = steady::now() + std::chrono::seconds(60);
        while (!stop && steady::now() < end && opened < 500000) {
            const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
            const linger reset{1, 0};
            ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &reset, sizeof reset);
            if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) {
                [[maybe_unused]] const auto n = ::send(fd, partial.data(), partial.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
                ++opened;
                held.push_back(fd);
            } else {
                ::close(fd);
            }
            if (held.size() > 256) {
                ::close(held.front());
                held.erase(held.begin());
            }
        }
        for (int fd : held) ::close(fd);
    });
    StopAndJoin join{stop, flood};

    // Ten seconds of flood from when it has filled the console's places (32) several times over.
    while (opened < 200) std::this_thread::yield();
    const auto t0 = steady::now();
    const std::size_t before = view.messages();
    const auto aborted = run_cli({"campaign", "abort", "--socket", d.socket.string(), "--reason", "flood test"});
    INFO("abort: exit " << aborted.exit_code << " after " << aborted.seconds << " s: " << aborted.output);
    CHECK(aborted.exit_code == 0);
    CHECK(aborted.seconds < 1.0);
    const bool up = view.stays_up_until(t0 + std::chrono::seconds(10));
    stop = true;
    INFO("the flood opened " << opened << " connections; the view " << (up ? "stayed up" : "dropped: " + view.drop_reason));
    CHECK(up);
    // Every 1-s interval of the ten received an update (one may miss, under the flood's load).
    int intervals_with_update = 0;
    {
        std::lock_guard lk(view.lock);
        for (int k = 0; k < 10; ++k) {
            const auto from = t0 + std::chrono::seconds(k), to = from + std::chrono::seconds(1);
            bool any = false;
            for (std::size_t i = before; i < view.arrivals.size(); ++i) any = any || (view.arrivals[i] >= from && view.arrivals[i] < to);
            intervals_with_update += any ? 1 : 0;
        }
    }
    INFO(intervals_with_update << " of 10 one-second intervals had an update");
    CHECK(intervals_with_update >= 9);
    CHECK(opened > 500);  // it was a flood
}
