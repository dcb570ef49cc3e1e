// Issue 14: no client can freeze control, one daemon per database and socket, a token no one
// else can read. Clients here misbehave on purpose (never read, write slowly, hold idle
// connections under a small open-file limit) while another client aborts a campaign.
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <poll.h>
#include <sys/random.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "daemon/control_api.hpp"
#include "base/user_error.hpp"
#include "daemon_fixture.hpp"
#include "daemon_process.hpp"

namespace fs = std::filesystem;
using manikind::ControlOptions;
using manikind::ControlServer;
using manikind::call_daemon;
using manikind::test::DaemonFixture;
using manikind::test::DaemonProcess;
using manikind::test::quick_plan;
using clock_type = std::chrono::steady_clock;

namespace {

std::string random_token() {
    unsigned char b[32];
    REQUIRE(::getrandom(b, sizeof b, 0) == static_cast<ssize_t>(sizeof b));
    std::string t;
    for (unsigned char c : b) t += fmt::format("{:02x}", c);
    return t;
}

int connect_unix(const fs::path& path, bool nonblocking) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | (nonblocking ? SOCK_NONBLOCK : 0), 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
        ::close(fd);
        return -errno;
    }
    return fd;
}

// Everything the server says on `fd` until it hangs up (or `limit_s` passes: then the test fails).
std::string read_until_closed(int fd, double limit_s) {
    std::string all;
    const auto end = clock_type::now() + std::chrono::duration_cast<clock_type::duration>(std::chrono::duration<double>(limit_s));
    for (;;) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - clock_type::now()).count();
        REQUIRE(left > 0);
        pollfd p{fd, POLLIN, 0};
        if (::poll(&p, 1, static_cast<int>(left)) <= 0) continue;
        char buf[65536];
        const ssize_t n = ::read(fd, buf, sizeof buf);
        if (n > 0) all.append(buf, static_cast<std::size_t>(n));
        else if (n == 0 || (errno != EAGAIN && errno != EINTR)) return all;
    }
}

std::string first_line(const fs::path& p) {
    std::ifstream in(p);
    std::string line;
    std::getline(in, line);
    return line;
}

// A Unix socket bound at `path` (listening or not): a stale leftover, or another program's.
int bound_socket(const fs::path& path, bool listening) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
    if (listening) REQUIRE(::listen(fd, 4) == 0);
    return fd;
}

// Aborts through the API and returns how long the answer took.
double timed_abort(const fs::path& socket, const std::string& token, nlohmann::json& reply) {
    const auto t0 = clock_type::now();
    reply = call_daemon(socket, {{"cmd", "abort"}, {"token", token}}, 5.0);
    return std::chrono::duration<double>(clock_type::now() - t0).count();
}

struct ServedFixture {
    explicit ServedFixture(std::function<void(ControlOptions&)> tweak = {}) {
        options.socket_path = fixture.dir() / "api.sock";
        options.token = random_token();
        if (tweak) tweak(options);
        server = std::make_unique<ControlServer>(fixture.daemon(), options);
        server->start();
        REQUIRE(fixture.daemon().start_campaign(quick_plan("hardening")).empty());
    }
    DaemonFixture fixture;
    ControlOptions options;
    std::unique_ptr<ControlServer> server;
};

}  // namespace

TEST_CASE("a client that never reads its replies is dropped past the bound, an abort meanwhile is answered "
          "within a second",
          "[daemon][api][hardening]") {
    ServedFixture s([](ControlOptions& o) { o.max_unread_reply_bytes = 2 * 1024 * 1024; });
    // 200 status requests on a non-blocking socket, replies never read (the reproduction).
    const int hog = connect_unix(s.options.socket_path, true);
    REQUIRE(hog >= 0);
    const std::string request = "{\"cmd\":\"status\"}\n";
    for (int i = 0; i < 200; ++i) REQUIRE(::send(hog, request.data(), request.size(), MSG_NOSIGNAL) == ssize_t(request.size()));
    // The hog's replies fill its socket; the server keeps serving others.
    nlohmann::json reply;
    CHECK(timed_abort(s.options.socket_path, s.options.token, reply) < 1.0);
    CHECK(reply["ok"] == true);
    CHECK(s.fixture.daemon().status_json()["campaign"].is_null());
    CHECK(s.server->counters().dropped_unread == 0);  // the hog is still there, its replies queued
    // It keeps asking without reading: once its unread replies pass the bound it is let go.
    for (int i = 0; i < 100000; ++i) {
        pollfd p{hog, POLLOUT, 0};
        REQUIRE(::poll(&p, 1, 5000) == 1);
        if (::send(hog, request.data(), request.size(), MSG_NOSIGNAL) < 0) break;
    }
    CHECK(s.server->counters().dropped_unread == 1);
    ::close(hog);
}

TEST_CASE("a slow writer cannot hold the server: abort is answered at once, the half-sent request times out",
          "[daemon][api][hardening]") {
    ServedFixture s([](ControlOptions& o) { o.request_timeout_s = 0.3; });
    const int slow = connect_unix(s.options.socket_path, false);
    REQUIRE(slow >= 0);
    const std::string half = "{\"cmd\":\"sta";
    REQUIRE(::send(slow, half.data(), half.size(), MSG_NOSIGNAL) == ssize_t(half.size()));
    nlohmann::json reply;
    CHECK(timed_abort(s.options.socket_path, s.options.token, reply) < 1.0);
    CHECK(reply["ok"] == true);
    const std::string last_word = read_until_closed(slow, 5.0);
    CHECK(last_word.find("request not completed within 0.3 s") != std::string::npos);
    CHECK(s.server->counters().timed_out == 1);
    ::close(slow);
}

TEST_CASE("idle clients beyond the cap make room for a new one, which is served, busy slots refuse with a reason",
          "[daemon][api][hardening]") {
    // One test process plays every client: no per-process cap here.
    ServedFixture s([](ControlOptions& o) {
        o.max_clients = 8;
        o.max_clients_per_peer = 4096;
    });
    std::vector<int> idle;
    for (int i = 0; i < 20; ++i) idle.push_back(connect_unix(s.options.socket_path, false));
    nlohmann::json reply;
    CHECK(timed_abort(s.options.socket_path, s.options.token, reply) < 1.0);
    CHECK(reply["ok"] == true);
    const auto c = s.server->counters();
    CHECK(c.max_clients == 8);
    CHECK(c.connected <= 8);
    CHECK(c.evicted_idle >= 13);
    // The first idle client was let go with a reason.
    CHECK(read_until_closed(idle.front(), 5.0).find("disconnected to make room") != std::string::npos);
    for (int fd : idle) ::close(fd);
}

TEST_CASE("when every slot is busy mid-request, a new client is refused with the reason", "[daemon][api][hardening]") {
    // A grace longer than the test: every half-sent request below is fresh, so keeps its place.
    ServedFixture s([](ControlOptions& o) {
        o.max_clients = 8;
        o.max_clients_per_peer = 4096;
        o.partial_grace_s = 60;
    });
    // Each sends a whole request and the first byte of the next in one write, and reads the reply:
    // once it has, the server holds that client's half-sent request.
    std::vector<int> busy;
    for (int i = 0; i < 8; ++i) {
        busy.push_back(connect_unix(s.options.socket_path, false));
        const std::string bytes = "{\"cmd\":\"live\"}\n{";
        REQUIRE(::send(busy.back(), bytes.data(), bytes.size(), MSG_NOSIGNAL) == ssize_t(bytes.size()));
        std::string line;
        char ch = 0;
        while (::read(busy.back(), &ch, 1) == 1 && ch != '\n') line += ch;
        REQUIRE(line.find("\"ok\":true") != std::string::npos);
    }
    const int ninth = connect_unix(s.options.socket_path, false);
    CHECK(read_until_closed(ninth, 5.0).find("refused: 8 clients are connected and busy") != std::string::npos);
    CHECK(s.server->counters().refused_full == 1);
    ::close(ninth);
    for (int fd : busy) ::close(fd);
}

TEST_CASE("control: a half-written request past the grace makes room before a client that never asked and one whose "
          "request was answered",
          "[daemon][api][hardening][lockout]") {
    ServedFixture s([](ControlOptions& o) {
        o.max_clients = 4;
        o.max_clients_per_peer = 4096;  // one test process plays every client
        o.partial_grace_s = 0;          // every half-written request is past it (the refusal test has the other side)
    });
    const std::string live = "{\"cmd\":\"live\"}\n";
    // A client that asks and reads its answer, then stays.
    auto asked = [&] {
        const int fd = connect_unix(s.options.socket_path, false);
        REQUIRE(::send(fd, live.data(), live.size(), MSG_NOSIGNAL) == ssize_t(live.size()));
        char ch = 0;
        while (::read(fd, &ch, 1) == 1 && ch != '\n') {
        }
        REQUIRE(ch == '\n');
        return fd;
    };
    const int answered = asked();
    const int silent = connect_unix(s.options.socket_path, false);
    std::vector<int> half;
    const std::string sta = "{\"cmd\":\"sta";
    for (int i = 0; i < 2; ++i) {
        half.push_back(connect_unix(s.options.socket_path, false));
        REQUIRE(::send(half.back(), sta.data(), sta.size(), MSG_NOSIGNAL) == ssize_t(sta.size()));
    }
    // Every place taken; each newcomer below takes one: the half-written requests (oldest first),
    // then the client that never asked, then the one answered longest ago.
    std::vector<int> newcomers{asked()};
    CHECK(read_until_closed(half[0], 5.0).find("its request was incomplete") != std::string::npos);
    newcomers.push_back(asked());
    CHECK(read_until_closed(half[1], 5.0).find("its request was incomplete") != std::string::npos);
    newcomers.push_back(asked());
    CHECK(read_until_closed(silent, 5.0).find("it had sent no request") != std::string::npos);
    nlohmann::json reply;
    CHECK(timed_abort(s.options.socket_path, s.options.token, reply) < 1.0);
    CHECK(reply["ok"] == true);
    CHECK(read_until_closed(answered, 5.0).find("it was the longest idle") != std::string::npos);
    CHECK(s.server->counters().evicted_idle == 4);
    pollfd p{newcomers[0], POLLIN, 0};
    CHECK(::poll(&p, 1, 0) == 0);  // the newer answered clients keep their places, nothing said
    for (int fd : {answered, silent, half[0], half[1]}) ::close(fd);
    for (int fd : newcomers) ::close(fd);
}

TEST_CASE("control: one process past its share of places loses its own oldest connection and no one else's",
          "[daemon][api][hardening][lockout]") {
    ServedFixture s([](ControlOptions& o) {
        o.max_clients = 16;
        o.max_clients_per_peer = 4;
    });
    std::vector<int> mine;
    for (int i = 0; i < 6; ++i) mine.push_back(connect_unix(s.options.socket_path, false));
    // The fifth and sixth each took the place of this process's oldest: the first two.
    CHECK(read_until_closed(mine[0], 5.0).find("newer connection of the same process") != std::string::npos);
    CHECK(read_until_closed(mine[1], 5.0).find("4 per process is the limit") != std::string::npos);
    const auto c = s.server->counters();
    CHECK(c.evicted_peer >= 2);
    CHECK(c.evicted_idle == 0);
    CHECK(c.max_clients_per_peer == 4);
    for (int fd : mine) ::close(fd);
}

TEST_CASE("an idle client is disconnected after idle_timeout_s", "[daemon][api][hardening]") {
    ServedFixture s([](ControlOptions& o) { o.idle_timeout_s = 0.3; });
    const int fd = connect_unix(s.options.socket_path, false);
    const std::string said = read_until_closed(fd, 5.0);
    CHECK(said.find("idle for 0.3 s; disconnected") != std::string::npos);
    ::close(fd);
}

TEST_CASE("the CLI's call gives up after its timeout and says what it waited for", "[daemon][api][hardening]") {
    DaemonFixture f;
    // A socket that listens but never answers: a hung daemon.
    const fs::path path = f.dir() / "hung.sock";
    const int listener = bound_socket(path, true);
    const auto t0 = clock_type::now();
    try {
        call_daemon(path, {{"cmd", "abort"}}, 0.3);
        FAIL("no timeout");
    } catch (const manikind::UserError& e) {
        CHECK(std::string(e.what()).find("within 0.3 s: waited for its reply ('abort')") != std::string::npos);
    }
    CHECK(std::chrono::duration<double>(clock_type::now() - t0).count() < 3.0);
    ::close(listener);
}

TEST_CASE("control: the CLI's call tries once more when the daemon turned it away and never sends a state-changing "
          "request twice",
          "[daemon][api][hardening][lockout]") {
    DaemonFixture f;
    const fs::path path = f.dir() / "fake.sock";
    const int listener = bound_socket(path, true);
    // A stand-in daemon: for each connection in turn, reads the request line and answers `replies[i]`
    // ("" closes without a word).
    auto serve = [&](std::vector<std::string> replies) {
        return std::thread([listener, replies] {
            for (const auto& reply : replies) {
                const int fd = ::accept(listener, nullptr, nullptr);
                std::string line;
                char ch = 0;
                while (::read(fd, &ch, 1) == 1 && ch != '\n') line += ch;
                if (!reply.empty()) {
                    [[maybe_unused]] const auto n = ::write(fd, reply.data(), reply.size());
                }
                ::close(fd);
            }
        });
    };
    const std::string refused = "{\"ok\":false,\"error\":\"refused: 64 clients are connected and busy\"}\n";
    const std::string second = "{\"ok\":true,\"second\":true}\n";
    SECTION("turned away: the second try is answered, even for a request that changes state") {
        auto t = serve({refused, second});
        CHECK(call_daemon(path, {{"cmd", "pause"}, {"token", "x"}}, 5.0)["second"] == true);
        t.join();
    }
    SECTION("closed without a reply: a read is asked again") {
        auto t = serve({"", second});
        CHECK(call_daemon(path, {{"cmd", "status"}}, 5.0)["second"] == true);
        t.join();
    }
    SECTION("closed without a reply: a state-changing request is not sent again") {
        auto t = serve({""});
        CHECK_THROWS_WITH(call_daemon(path, {{"cmd", "pause"}, {"token", "x"}}, 5.0), Catch::Contains("without replying"));
        t.join();
        pollfd p{listener, POLLIN, 0};
        CHECK(::poll(&p, 1, 0) == 0);  // the call has returned: a second try would be waiting here
    }
    ::close(listener);
}

TEST_CASE("a second daemon on the same database or socket is refused with the holder's PID, the first is unharmed",
          "[daemon][lock][hardening]") {
    ServedFixture first;
    const std::string pid = std::to_string(::getpid());
    // Same database, another socket.
    try {
        auto c = manikind::config::default_config();
        c.database = first.fixture.dir() / "test.db";
        c.simulation.runtime_dir = (first.fixture.dir() / "sim2").string();
        c.log_level = "error";
        manikind::LabDaemon second({c, true, 1.0});
        FAIL("the second daemon opened the first one's database");
    } catch (const manikind::UserError& e) {
        CHECK(std::string(e.what()).find("database") != std::string::npos);
        CHECK(std::string(e.what()).find("in use by another manikind (PID " + pid) != std::string::npos);
    }
    // Same socket, another database.
    DaemonFixture other;
    ControlOptions o = first.options;
    ControlServer second(other.daemon(), o);
    CHECK_THROWS_WITH(second.start(), Catch::Contains("control socket") && Catch::Contains("PID " + pid));
    // The first still answers, and its trial was not marked interrupted.
    const auto status = call_daemon(first.options.socket_path, {{"cmd", "status"}}, 5.0);
    CHECK(status["ok"] == true);
    CHECK(status["status"]["campaign"] == "hardening");
    CHECK(fs::exists(first.options.socket_path));
}

TEST_CASE("a stale socket is replaced, a live one or a file that is not a socket never is", "[daemon][lock][hardening]") {
    DaemonFixture f;
    ControlOptions o;
    o.token = random_token();
    SECTION("stale: a socket file no one listens on") {
        o.socket_path = f.dir() / "stale.sock";
        ::close(bound_socket(o.socket_path, false));  // the killed daemon's leftover
        ControlServer server(f.daemon(), o);
        server.start();
        CHECK(call_daemon(o.socket_path, {{"cmd", "status"}}, 5.0)["ok"] == true);
    }
    SECTION("live: another program listens there") {
        o.socket_path = f.dir() / "live.sock";
        const int fd = bound_socket(o.socket_path, true);
        ControlServer server(f.daemon(), o);
        CHECK_THROWS_WITH(server.start(), Catch::Contains("another process answers on"));
        CHECK(fs::is_socket(o.socket_path));
        ::close(fd);
    }
    SECTION("a regular file") {
        o.socket_path = f.dir() / "notes.txt";
        std::ofstream(o.socket_path) << "keep me\n";
        ControlServer server(f.daemon(), o);
        CHECK_THROWS_WITH(server.start(), Catch::Contains("exists and is not a socket"));
        CHECK(first_line(o.socket_path) == "keep me");
    }
}

TEST_CASE("the token file is never written through a symlink nor kept readable by others", "[daemon][token][hardening]") {
    DaemonFixture f;
    const fs::path socket = f.dir() / "t.sock";
    const fs::path token_file = f.dir() / "t.sock.token";
    SECTION("a symlink at the token path: its target is untouched") {
        const fs::path target = f.dir() / "victim";
        std::ofstream(target) << "precious\n";
        fs::permissions(target, fs::perms(0644));
        fs::create_symlink(target, token_file);
        CHECK_THROWS_WITH(manikind::load_or_create_token("", socket), Catch::Contains("symbolic link"));
        CHECK(first_line(target) == "precious");
        CHECK((fs::status(target).permissions() & fs::perms::all) == fs::perms(0644));
    }
    SECTION("a 0644 file at the token path: refused, neither written nor widened") {
        std::ofstream(token_file) << "old\n";
        fs::permissions(token_file, fs::perms(0644));
        CHECK_THROWS_WITH(manikind::load_or_create_token("", socket), Catch::Contains("mode 0644"));
        CHECK(first_line(token_file) == "old");
        CHECK((fs::status(token_file).permissions() & fs::perms::all) == fs::perms(0644));
    }
    SECTION("no file, or the daemon's own 0600 file: a fresh 0600 token") {
        const std::string first = manikind::load_or_create_token("", socket);
        CHECK(first.size() == 64);
        CHECK((fs::symlink_status(token_file).permissions() & fs::perms::all) == fs::perms(0600));
        const std::string second = manikind::load_or_create_token("", socket);
        CHECK(second != first);
        CHECK(manikind::read_token_file(socket) == second);
        CHECK((fs::symlink_status(token_file).permissions() & fs::perms::all) == fs::perms(0600));
    }
}

TEST_CASE("the database and its WAL are created 0640 or tighter", "[daemon][hardening]") {
    DaemonFixture f;
    f.daemon().step_virtual(10.0);
    for (const char* name : {"test.db", "test.db-wal"}) {
        const fs::path p = f.dir() / name;
        REQUIRE(fs::exists(p));
        const auto mode = static_cast<unsigned>(fs::status(p).permissions() & fs::perms::all);
        INFO(name << " mode " << std::oct << mode);
        CHECK((mode & 0027u) == 0u);
    }
}

namespace {
const std::string daemon_bin = std::string(MANIKIND_BIN_DIR) + "/manikind";

fs::path fresh_dir(const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-{}-{}", name, ::getpid());
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

std::string slurp(const fs::path& p) {
    std::ifstream in(p);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
}  // namespace

TEST_CASE("a second manikind process on the same database or socket exits with the first one's PID and touches "
          "nothing of it",
          "[daemon][lock][hardening]") {
    const fs::path dir = fresh_dir("two-daemons");
    auto first = DaemonProcess::spawn({daemon_bin, "--socket", (dir / "a.sock").string(), "--database",
                                       (dir / "a.db").string(), "--campaign", "builtin:table-s3"});
    REQUIRE(first.read_until("control socket"));
    const std::string token_before = slurp(dir / "a.sock.token");
    const std::string holder = "in use by another manikind (PID " + std::to_string(first.pid());

    auto same_db = DaemonProcess::spawn({daemon_bin, "--socket", (dir / "b.sock").string(), "--database",
                                         (dir / "a.db").string()});
    const int db_status = same_db.wait();
    CHECK(WEXITSTATUS(db_status) == 2);
    CHECK(same_db.output().find("the database " + (dir / "a.db").string() + " is " + holder) != std::string::npos);

    auto same_socket = DaemonProcess::spawn({daemon_bin, "--socket", (dir / "a.sock").string(), "--database",
                                             (dir / "b.db").string()});
    const int socket_status = same_socket.wait();
    CHECK(WEXITSTATUS(socket_status) == 2);
    CHECK(same_socket.output().find("the control socket " + (dir / "a.sock").string() + " is " + holder) != std::string::npos);
    CHECK_FALSE(fs::exists(dir / "b.db"));                  // refused before it made a database
    CHECK(slurp(dir / "a.sock.token") == token_before);     // nor replaced the first one's token

    // The first is unharmed: it answers, and its trial is still the live one.
    const auto status = call_daemon(dir / "a.sock", {{"cmd", "status"}}, 5.0);
    CHECK(status["status"]["campaign"] == "table-s3");
    CHECK(WEXITSTATUS(first.terminate()) == 0);
    fs::remove_all(dir);
}

TEST_CASE("under systemd the daemon says READY=1 once its socket answers, feeds the watchdog, and says STOPPING=1",
          "[daemon][systemd][hardening]") {
    const fs::path dir = fresh_dir("notify");
    const fs::path notify = dir / "notify.sock";
    const int listener = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", notify.c_str());
    REQUIRE(::bind(listener, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
    DaemonProcess::Options env;
    env.env = {{"NOTIFY_SOCKET", notify.string()}, {"WATCHDOG_USEC", "300000"}};
    auto d = DaemonProcess::spawn({daemon_bin, "--socket", (dir / "d.sock").string(), "--database", (dir / "d.db").string()},
                                  env);
    auto next_message = [&] {
        pollfd p{listener, POLLIN, 0};
        REQUIRE(::poll(&p, 1, 20000) == 1);
        char buf[4096];
        const ssize_t n = ::recv(listener, buf, sizeof buf, 0);
        REQUIRE(n > 0);
        return std::string(buf, static_cast<std::size_t>(n));
    };
    const std::string ready = next_message();
    CHECK(ready.rfind("READY=1", 0) == 0);
    CHECK(call_daemon(dir / "d.sock", {{"cmd", "status"}}, 5.0)["ok"] == true);  // ready means reachable
    int pings = 0;
    while (pings < 3) {
        const std::string m = next_message();
        REQUIRE(m == "WATCHDOG=1");
        ++pings;
    }
    ::kill(d.pid(), SIGTERM);
    std::string m;
    do m = next_message();
    while (m == "WATCHDOG=1");
    CHECK(m == "STOPPING=1");
    CHECK(WEXITSTATUS(d.wait()) == 0);
    ::close(listener);
    fs::remove_all(dir);
}

TEST_CASE("300 idle clients against a daemon limited to 128 open files: abort answered within a second, CPU stays "
          "low, the instruments stay connected",
          "[daemon][api][hardening]") {
    const fs::path dir = fresh_dir("idle-300");
    const std::string token = random_token();
    const fs::path cfg = dir / "lab.toml";
    std::ofstream(cfg) << fmt::format("[lab]\ndatabase = \"{}\"\n[api]\nsocket = \"{}\"\ntoken = \"{}\"\nidle_timeout_s = 2\n"
                                      "[simulation]\nruntime_dir = \"{}\"\n",
                                      (dir / "d.db").string(), (dir / "d.sock").string(), token, (dir / "sim").string());
    fs::permissions(cfg, fs::perms(0600));
    DaemonProcess::Options limited;
    limited.max_open_files = 128;
    auto d = DaemonProcess::spawn({daemon_bin, "--config", cfg.string()}, limited);
    REQUIRE(d.read_until("control socket"));
    // Started through the API, not --campaign: the socket line is printed before --campaign
    // starts, and on a loaded machine the abort came first ("no campaign is running").
    const auto started = call_daemon(dir / "d.sock", {{"cmd", "start_campaign"}, {"builtin", "table-s3"}, {"name", "idle-300"},
                                                      {"token", token}}, 30.0);
    INFO(started.dump());
    REQUIRE(started["ok"] == true);

    rlimit mine{};
    ::getrlimit(RLIMIT_NOFILE, &mine);
    mine.rlim_cur = mine.rlim_max;
    ::setrlimit(RLIMIT_NOFILE, &mine);
    REQUIRE(mine.rlim_cur >= 400);

    const double cpu0 = d.cpu_seconds();
    const auto t0 = clock_type::now();
    std::vector<int> clients;
    int refused_by_backlog = 0;
    for (int i = 0; i < 300; ++i) {
        const int fd = connect_unix(dir / "d.sock", true);
        if (fd == -EAGAIN) ++refused_by_backlog;
        else if (fd >= 0) clients.push_back(fd);
    }
    CHECK(refused_by_backlog == 0);  // the backlog (4096) holds them while the server accepts
    nlohmann::json reply;
    CHECK(timed_abort(dir / "d.sock", token, reply) < 1.0);
    INFO(reply.dump());
    CHECK(reply["ok"] == true);
    // Wait for a real event: the newest idle client timed out by the daemon (2 s). Over that
    // time a daemon spinning on accept would burn a whole core.
    REQUIRE(!clients.empty());
    CHECK(read_until_closed(clients.back(), 15.0).find("idle for 2 s") != std::string::npos);
    const double cpu_fraction = (d.cpu_seconds() - cpu0) / std::chrono::duration<double>(clock_type::now() - t0).count();
    INFO("daemon CPU " << cpu_fraction * 100 << " % of one core");
    CHECK(cpu_fraction < 0.25);
    const auto status = call_daemon(dir / "d.sock", {{"cmd", "status"}}, 5.0);
    for (const auto& dev : status["status"]["devices"]) {
        INFO(dev["name"]);
        CHECK(dev["connected"] == true);
    }
    for (int fd : clients) ::close(fd);
    CHECK(WEXITSTATUS(d.terminate()) == 0);
    fs::remove_all(dir);
}
