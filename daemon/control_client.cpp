// The control API's client side: what `manikin` and the tests use to talk to a running daemon.
#include "daemon/control_client.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>

#include "base/user_error.hpp"

namespace manikind {

namespace {

using client_clock = std::chrono::steady_clock;

// Waits for `events` on `fd` until `deadline`; false on timeout.
bool wait_for(int fd, short events, client_clock::time_point deadline) {
    for (;;) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - client_clock::now()).count();
        if (left <= 0) return false;
        pollfd p{fd, events, 0};
        const int rc = ::poll(&p, 1, static_cast<int>(std::min<long long>(left, 1000)));
        if (rc > 0) return true;
        if (rc < 0 && errno != EINTR) return true;  // let the read/write report the error
    }
}

}  // namespace

sockaddr_un unix_address(const std::string& path, const std::string& what) {
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.size() >= sizeof addr.sun_path)
        throw UserError(fmt::format("{} path is {} characters, over the limit of {}: {}", what, path.size(),
                                    sizeof addr.sun_path - 1, path));
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    return addr;
}

namespace {

// How one attempt ended when it brought no reply. `not_carried_out`: the daemon cannot have acted
// on the request (no connection, or it hung up with the request unread); `closed`: it hung up
// without a word, after the request may have been read.
struct Attempt {
    nlohmann::json reply;
    enum { replied, not_carried_out, closed } outcome = replied;
    std::string why;
};

Attempt call_once(const std::string& path, const nlohmann::json& request, client_clock::time_point deadline,
                  const std::function<UserError(const char*)>& timed_out) {
    sockaddr_un addr = unix_address(path, "socket");
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) throw UserError(fmt::format("cannot create a socket: {}", std::strerror(errno)));
    struct Closer {
        int fd;
        ~Closer() { ::close(fd); }
    } closer{fd};
    // A Unix connect fails with EAGAIN while the daemon's backlog is full: retry until the deadline.
    for (;;) {
        if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) break;
        if (errno == EAGAIN || errno == EINTR) {
            if (client_clock::now() >= deadline) throw timed_out("a free place in its connection queue");
            pollfd none{-1, 0, 0};
            ::poll(&none, 1, 20);
            continue;
        }
        if (errno == EINPROGRESS) {
            if (!wait_for(fd, POLLOUT, deadline)) throw timed_out("it to accept the connection");
            int err = 0;
            socklen_t len = sizeof err;
            ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
            if (err == 0) break;
            errno = err;
        }
        return {nullptr, Attempt::not_carried_out,
                fmt::format("cannot reach the daemon at {}: {} (is manikind running? --socket)", path, std::strerror(errno))};
    }
    // A reset means the daemon closed with our bytes unread (a refusal whose last word was lost).
    auto hung_up = [&](int err) {
        return Attempt{nullptr, err == ECONNRESET || err == EPIPE ? Attempt::not_carried_out : Attempt::closed,
                       fmt::format("the daemon at {} closed the connection: {}", path, std::strerror(err))};
    };
    const std::string msg = request.dump() + "\n";
    for (std::size_t sent = 0; sent < msg.size();) {
        const ssize_t n = ::send(fd, msg.data() + sent, msg.size() - sent, MSG_NOSIGNAL);
        if (n > 0) {
            sent += static_cast<std::size_t>(n);
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
            if (!wait_for(fd, POLLOUT, deadline)) throw timed_out("it to take the request");
            continue;
        }
        return hung_up(errno);
    }
    std::string reply;
    char buf[65536];
    while (reply.empty() || reply.back() != '\n') {
        const ssize_t n = ::read(fd, buf, sizeof buf);
        if (n > 0) {
            reply.append(buf, static_cast<std::size_t>(n));
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
            if (!wait_for(fd, POLLIN, deadline)) throw timed_out("its reply");
            continue;
        }
        if (reply.empty()) {
            if (n < 0) return hung_up(errno);
            return {nullptr, Attempt::closed, fmt::format("the daemon at {} closed the connection without replying", path)};
        }
        break;
    }
    const auto j = nlohmann::json::parse(reply, nullptr, false);
    if (j.is_discarded())
        throw UserError::unreachable("the daemon's reply is not JSON: " + reply.substr(0, 200), "daemon_bad_reply");
    return {j, Attempt::replied, {}};
}

// The daemon's own word that it let this connection go before reading a request: its place was
// full ("refused: ...") or taken for a newcomer ("disconnected ..."). Nothing was carried out.
bool daemon_turned_away(const nlohmann::json& reply) {
    if (!reply.is_object() || reply.value("ok", true)) return false;
    const std::string why = reply.value("error", std::string());
    return why.rfind("refused:", 0) == 0 || why.rfind("disconnected", 0) == 0;
}

// Doing these twice leaves the daemon as doing them once: reads, and abort (the second finds no
// campaign running).
bool idempotent(const std::string& cmd) {
    static const char* const safe[] = {"status", "live", "results", "alarms", "alarm_history", "notes", "campaign_outcome", "abort"};
    return std::any_of(std::begin(safe), std::end(safe), [&](const char* c) { return cmd == c; });
}

}  // namespace

nlohmann::json call_daemon(const std::filesystem::path& socket_path, const nlohmann::json& request, double timeout_s) {
    const std::string path = socket_path.string();
    const std::string cmd = request.value("cmd", std::string("?"));
    const auto deadline = client_clock::now() + std::chrono::duration_cast<client_clock::duration>(
                                                    std::chrono::duration<double>(timeout_s));
    auto timed_out = [&](const char* waiting_for) {
        return UserError::unreachable(fmt::format("no answer from the daemon at {} within {} s: waited for {} ('{}'). It may "
                                                  "be hung or overloaded: see its log (journalctl -u manikind), or try a "
                                                  "longer --timeout",
                                                  path, timeout_s, waiting_for, cmd),
                                      "daemon_timeout");
    };
    // One more try after a short pause, only where the first cannot have been carried out (no
    // connection, or the daemon turned it away unread) or where carrying it out twice does no
    // harm: a daemon full of clients, or restarting, answers the second (docs/daemon.md).
    constexpr auto retry_pause = std::chrono::milliseconds(150);
    for (int attempt = 1;; ++attempt) {
        Attempt a = call_once(path, request, deadline, timed_out);
        const bool may_retry = a.outcome == Attempt::not_carried_out || daemon_turned_away(a.reply) ||
                               (a.outcome == Attempt::closed && idempotent(cmd));
        if (attempt == 1 && may_retry && client_clock::now() + retry_pause < deadline) {
            pollfd none{-1, 0, 0};
            ::poll(&none, 1, static_cast<int>(retry_pause.count()));
            continue;
        }
        if (a.outcome != Attempt::replied) throw UserError::unreachable(a.why);
        return a.reply;
    }
}

std::string read_token_file(const std::filesystem::path& socket_path) {
    std::ifstream in(socket_path.string() + ".token");
    std::string token;
    std::getline(in, token);
    return token;
}

}  // namespace manikind
