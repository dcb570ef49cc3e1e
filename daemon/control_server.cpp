// The control API's server: one Boost.Asio thread, every client asynchronous, every limit a drop
// or a refusal, never a blocked call. Rules (docs/daemon.md, "Control API"):
//   - requests are read as they come; each reply is queued on its own client and written
//     asynchronously, so a client that never reads only fills its own queue; past
//     max_unread_reply_bytes (or a write stalled for idle_timeout_s) it is dropped;
//   - a request line must arrive whole within request_timeout_s of its first byte (slow writers);
//   - a client that sends nothing for idle_timeout_s is disconnected;
//   - at most max_clients (lowered to fit RLIMIT_NOFILE, leaving descriptors for the drivers);
//     a new client beyond it takes the place of another, in this order: a half-written request
//     older than partial_grace_s (oldest first), a client that never sent a request (oldest
//     first), a client whose requests were all answered (longest idle first). A client mid-reply
//     or with a request still arriving within the grace keeps its place; only when every place is
//     such is the newcomer refused, with a clear reply (the CLI retries once). So holding places
//     with half-written requests cannot lock status or abort out;
//   - one process (SO_PEERCRED pid) holds at most max_clients_per_peer connections; a newer one
//     of its own takes the place of its least useful one, so it can crowd out only itself (never
//     refused for it: a reused pid must not lock a newcomer out);
//   - out of file descriptors, accept is retried after a pause (never spun) once an idle client
//     has been let go.
#include <arpa/inet.h>
#include <pwd.h>
#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <boost/asio/basic_socket_acceptor.hpp>
#include <boost/asio/generic/stream_protocol.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "daemon/control_api.hpp"
#include "base/guarded.hpp"
#include "daemon/instance_lock.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace asio = boost::asio;
using stream = asio::generic::stream_protocol;
using acceptor_t = asio::basic_socket_acceptor<stream>;
using SteadyClock = std::chrono::steady_clock;

namespace {

std::chrono::nanoseconds seconds(double s) {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(s));
}

bool is_power_of_two(std::uint64_t n) { return n != 0 && (n & (n - 1)) == 0; }

std::string error_line(const std::string& why) { return dump_json(nlohmann::json{{"ok", false}, {"error", why}}) + "\n"; }

// A last word to a client being let go, only if its socket takes it at once: never blocks.
void say_goodbye(int fd, const std::string& why) {
    const std::string line = error_line(why);
    [[maybe_unused]] const auto n = ::send(fd, line.data(), line.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
}

int count_open_fds() {
    std::error_code ec;
    int n = 0;
    for (std::filesystem::directory_iterator it("/proc/self/fd", ec), end; !ec && it != end; it.increment(ec)) ++n;
    return n;
}

// A stale socket file (its daemon died) refuses connections; a live one accepts or has a full backlog.
bool someone_answers(const std::string& path) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) return false;
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    const int rc = ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
    const int err = errno;
    ::close(fd);
    return rc == 0 || err == EAGAIN || err == EINPROGRESS;
}

}  // namespace

// The peer's process on the Unix socket (SO_PEERCRED), 0 over TCP.
static pid_t peer_pid(stream::socket& socket) {
    ucred cred{};
    socklen_t len = sizeof cred;
    if (::getsockopt(socket.native_handle(), SOL_SOCKET, SO_PEERCRED, &cred, &len) == 0 && len == sizeof cred) return cred.pid;
    return 0;
}

// Who is at the other end: on the Unix socket the kernel's word (SO_PEERCRED: user, uid, pid);
// over TCP (127.0.0.1 only) the address.
static std::string peer_of(stream::socket& socket) {
    const int fd = socket.native_handle();
    ucred cred{};
    socklen_t len = sizeof cred;
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) == 0 && len == sizeof cred && cred.pid > 0) {
        std::string user = std::to_string(cred.uid);
        std::array<char, 1024> buffer{};
        passwd pw{};
        passwd* found = nullptr;
        if (::getpwuid_r(cred.uid, &pw, buffer.data(), buffer.size(), &found) == 0 && found) user = found->pw_name;
        return fmt::format("user {} (uid {}, pid {}) on the control socket", printable(user), cred.uid, cred.pid);
    }
    sockaddr_storage addr{};
    socklen_t alen = sizeof addr;
    if (::getpeername(fd, reinterpret_cast<sockaddr*>(&addr), &alen) == 0 && addr.ss_family == AF_INET) {
        const auto* in = reinterpret_cast<const sockaddr_in*>(&addr);
        std::array<char, INET_ADDRSTRLEN> ip{};
        ::inet_ntop(AF_INET, &in->sin_addr, ip.data(), ip.size());
        return fmt::format("{}:{} over TCP", ip.data(), ntohs(in->sin_port));
    }
    return "a control-socket client";
}

struct ControlServer::Impl {
    struct Session : std::enable_shared_from_this<Session> {
        Session(Impl& server, stream::socket s, std::uint64_t session_id)
            : owner(server), socket(std::move(s)), id(session_id), who(peer_of(socket)), pid(peer_pid(socket)),
              last_activity(SteadyClock::now()) {}
        Impl& owner;
        stream::socket socket;
        std::uint64_t id;
        std::string who;  // the peer, as an abort records it
        pid_t pid;        // the peer process (Unix socket), 0 over TCP: its connections share a cap
        std::array<char, 4096> read_buffer{};
        std::string pending_input;                  // bytes of a request line not yet complete
        std::optional<SteadyClock::time_point> partial_since;
        std::deque<std::string> replies;            // queued, unwritten (front: being written)
        std::size_t reply_bytes = 0;
        bool writing = false, close_after_write = false, closed = false;
        SteadyClock::time_point last_activity;           // last byte in, or last reply fully written
        SteadyClock::time_point write_started;
        std::optional<SteadyClock::time_point> last_request;  // none yet: the first to go when room is needed

        void read() {
            socket.async_read_some(asio::buffer(read_buffer), [self = shared_from_this()](const boost::system::error_code& ec,
                                                                                          std::size_t n) {
                self->on_read(ec, n);
            });
        }

        void on_read(const boost::system::error_code& ec, std::size_t n) {
            if (closed) return;
            if (ec) return owner.close(*this, {});
            const auto now = SteadyClock::now();
            last_activity = now;
            pending_input.append(read_buffer.data(), n);
            if (!partial_since) partial_since = now;
            std::size_t start = 0;
            for (auto nl = pending_input.find('\n', start); nl != std::string::npos; nl = pending_input.find('\n', start)) {
                const std::string line = pending_input.substr(start, nl - start);
                start = nl + 1;
                last_request = now;
                queue(owner.answer(line, who));
                if (closed) return;
            }
            pending_input.erase(0, start);
            if (start > 0) partial_since = pending_input.empty() ? std::nullopt : std::optional(now);
            if (pending_input.size() > owner.o.max_message_bytes) {  // oversized: refuse and hang up
                queue(error_line(fmt::format("message over the limit of {} bytes; connection closed", owner.o.max_message_bytes)));
                close_after_write = true;
                return;
            }
            if (reply_bytes > owner.o.max_unread_reply_bytes) {
                ++owner.counters.dropped_unread;
                return owner.close(*this, fmt::format("{} bytes of replies unread (limit {}); disconnected", reply_bytes,
                                                      owner.o.max_unread_reply_bytes));
            }
            read();
        }

        void queue(std::string reply) {
            reply_bytes += reply.size();
            replies.push_back(std::move(reply));
            if (!writing) write_front();
        }

        void write_front() {
            if (replies.empty()) {
                writing = false;
                if (close_after_write) owner.close(*this, {});
                return;
            }
            writing = true;
            write_started = SteadyClock::now();
            asio::async_write(socket, asio::buffer(replies.front()),
                              [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                                  if (self->closed) return;
                                  if (ec) return self->owner.close(*self, {});
                                  self->reply_bytes -= self->replies.front().size();
                                  self->replies.pop_front();
                                  self->last_activity = SteadyClock::now();
                                  self->write_front();
                              });
        }

        bool idle() const { return !writing && replies.empty() && pending_input.empty(); }
    };

    // How readily a client gives up its place to a newcomer: the lower the sooner; none: it keeps
    // it. 0: a half-written request older than partial_grace_s (by its first byte); 1: never sent
    // a request (by connection time); 2: all its requests answered (by last activity). Mid-reply,
    // or a request arriving within the grace: kept, except that a process making room for its
    // own newcomer (`own`) may lose a fresh half-written request too, last.
    struct Rank {
        int order;
        SteadyClock::time_point since;
        bool operator<(const Rank& r) const { return order != r.order ? order < r.order : since < r.since; }
    };
    std::optional<Rank> eviction_rank(const Session& s, SteadyClock::time_point now, bool own) const {
        if (s.writing || !s.replies.empty()) return std::nullopt;
        if (!s.pending_input.empty()) {
            const auto since = s.partial_since.value_or(s.last_activity);
            if (now - since >= seconds(o.partial_grace_s)) return Rank{0, since};
            return own ? std::optional(Rank{3, since}) : std::nullopt;
        }
        return s.last_request ? Rank{2, s.last_activity} : Rank{1, s.last_activity};
    }

    Impl(LabDaemon& d, ControlOptions options) : daemon(d), o(std::move(options)) {}

    LabDaemon& daemon;
    ControlOptions o;
    asio::io_context io;
    std::vector<std::unique_ptr<acceptor_t>> acceptors;
    std::optional<asio::steady_timer> sweep_timer, accept_retry_timer;
    std::map<std::uint64_t, std::shared_ptr<Session>> sessions;
    std::uint64_t next_id = 1;
    std::thread thread;
    std::atomic<bool> shutdown{false};
    std::atomic<std::int64_t> heartbeat_ns{0};
    InstanceLock socket_lock;
    struct stat bound{};
    bool socket_bound = false;
    int bound_tcp_port = 0;
    mutable std::mutex counters_lock;  // counters are written on the server thread, read by status
    ControlServerCounters counters;
    SteadyClock::time_point last_accept_error_log{};

    std::string answer(const std::string& line, const std::string& who = "a control-socket client") {
        bool shutdown_now = false;
        std::string reply;
        try {
            reply = dump_json(handle_request(daemon, o, line, shutdown_now, RequestOrigin{who, false})) + "\n";
        } catch (const std::exception& e) {  // never out of the server thread: that would end the daemon
            spdlog::error("control API: a request failed: {}", printable(e.what()));
            reply = error_line(fmt::format("internal error: {}", printable(e.what())));
        }
        // Flag before replying: a client that reads "ok" must find the shutdown requested.
        if (shutdown_now) shutdown = true;
        return reply;
    }

    // `logged`: false for the evictions a flood makes by the thousand (admit logs a sample of them).
    void close(Session& s, const std::string& goodbye, bool logged = true) {
        if (s.closed) return;
        s.closed = true;
        if (!goodbye.empty() && !s.writing) say_goodbye(s.socket.native_handle(), goodbye);
        if (!goodbye.empty() && logged) spdlog::info("control API: client {} {}", s.id, goodbye);
        boost::system::error_code ignored;
        s.socket.shutdown(stream::socket::shutdown_both, ignored);
        s.socket.close(ignored);
        std::lock_guard lk(counters_lock);
        sessions.erase(s.id);
        counters.connected = sessions.size();
    }

    // The client that makes room for a newcomer (eviction_rank), among those of process `pid`
    // when it is not 0; none when every candidate keeps its place.
    Session* eviction_victim(pid_t pid = 0) {
        const auto now = SteadyClock::now();
        Session* pick = nullptr;
        std::optional<Rank> best;
        for (auto& [id, s] : sessions) {
            if (pid != 0 && s->pid != pid) continue;
            const auto r = eviction_rank(*s, now, pid != 0);
            if (r && (!best || *r < *best)) {
                best = r;
                pick = s.get();
            }
        }
        return pick;
    }

    static const char* why_chosen(const Session& s) {
        if (!s.pending_input.empty()) return "its request was incomplete";
        return s.last_request ? "it was the longest idle" : "it had sent no request";
    }

    void admit(stream::socket socket) {
        {
            std::lock_guard lk(counters_lock);
            ++counters.accepted;
        }
        // One process first makes room among its own connections.
        if (const pid_t pid = peer_pid(socket); pid > 0) {
            std::size_t own = 0;
            for (const auto& [id, s] : sessions) own += s->pid == pid ? 1 : 0;
            if (own >= counters.max_clients_per_peer) {
                if (Session* victim = eviction_victim(pid)) {
                    std::uint64_t n = 0;
                    {
                        std::lock_guard lk(counters_lock);
                        n = ++counters.evicted_peer;
                    }
                    const std::string why = fmt::format("disconnected to make room for a newer connection of the same process "
                                                        "(pid {}): {} per process is the limit (api.max_clients_per_peer) and {}",
                                                        pid, counters.max_clients_per_peer, why_chosen(*victim));
                    if (is_power_of_two(n)) spdlog::info("control API: client {} {} ({} so far)", victim->id, why, n);
                    close(*victim, why, false);
                }
            }
        }
        if (sessions.size() >= counters.max_clients) {
            if (Session* victim = eviction_victim()) {
                std::uint64_t n = 0;
                {
                    std::lock_guard lk(counters_lock);
                    n = ++counters.evicted_idle;
                }
                const std::string why = fmt::format("disconnected to make room: {} clients is the limit (api.max_clients) and {}",
                                                    counters.max_clients, why_chosen(*victim));
                if (is_power_of_two(n)) spdlog::info("control API: client {} {} ({} so far)", victim->id, why, n);
                close(*victim, why, false);
            } else {
                std::uint64_t n = 0;
                {  // counted before the client can read the refusal
                    std::lock_guard lk(counters_lock);
                    n = ++counters.refused_full;
                }
                if (is_power_of_two(n))
                    spdlog::info("control API: a new client refused: every place mid-reply or with a request arriving ({} so far)", n);
                say_goodbye(socket.native_handle(),
                            fmt::format("refused: {} clients are connected and busy (api.max_clients); try again shortly",
                                        counters.max_clients));
                boost::system::error_code ignored;
                socket.close(ignored);
                return;
            }
        }
        auto s = std::make_shared<Session>(*this, std::move(socket), next_id++);
        {
            std::lock_guard lk(counters_lock);
            sessions.emplace(s->id, s);
            counters.connected = sessions.size();
        }
        s->read();
    }

    void accept(acceptor_t& acceptor) {
        acceptor.async_accept([this, &acceptor](const boost::system::error_code& ec, stream::socket socket) {
            if (ec == asio::error::operation_aborted) return;
            if (!ec) {
                admit(std::move(socket));
                return accept(acceptor);
            }
            {
                std::lock_guard lk(counters_lock);
                ++counters.accept_errors;
            }
            const auto now = SteadyClock::now();
            if (now - last_accept_error_log > std::chrono::seconds(10)) {
                spdlog::warn("control API: accept failed ({}); {} clients connected; retrying", ec.message(), sessions.size());
                last_accept_error_log = now;
            }
            // Out of descriptors: let the longest-idle client go and try at once; with none to let
            // go, wait a little instead of spinning on an accept that cannot succeed.
            if (Session* victim = eviction_victim()) {
                close(*victim, "disconnected: the daemon is out of file descriptors");
                return accept(acceptor);
            }
            accept_retry_timer->expires_after(std::chrono::milliseconds(100));
            accept_retry_timer->async_wait([this, &acceptor](const boost::system::error_code& wait_ec) {
                if (!wait_ec) accept(acceptor);
            });
        });
    }

    void sweep() {
        const auto now = SteadyClock::now();
        heartbeat_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now.time_since_epoch()).count();
        std::vector<std::pair<Session*, std::string>> expired;
        for (auto& [id, s] : sessions) {
            if (s->writing && now - s->write_started > seconds(o.idle_timeout_s))
                expired.emplace_back(s.get(), fmt::format("replies unread for {} s; disconnected", o.idle_timeout_s));
            else if (s->partial_since && now - *s->partial_since > seconds(o.request_timeout_s))
                expired.emplace_back(s.get(), fmt::format("request not completed within {} s (one JSON object per line); "
                                                          "disconnected",
                                                          o.request_timeout_s));
            else if (s->idle() && now - s->last_activity > seconds(o.idle_timeout_s))
                expired.emplace_back(s.get(), fmt::format("idle for {} s; disconnected", o.idle_timeout_s));
        }
        for (auto& [s, why] : expired) {
            {
                std::lock_guard lk(counters_lock);
                ++counters.timed_out;
            }
            close(*s, why);
        }
        sweep_timer->expires_after(std::chrono::milliseconds(100));
        sweep_timer->async_wait([this](const boost::system::error_code& ec) {
            if (!ec) sweep();
        });
    }
};

ControlServer::ControlServer(LabDaemon& daemon, ControlOptions options)
    : impl_(std::make_unique<Impl>(daemon, std::move(options))) {}
ControlServer::~ControlServer() { stop(); }

bool ControlServer::shutdown_requested() const { return impl_->shutdown.load(); }
int ControlServer::tcp_port() const { return impl_->bound_tcp_port; }

double ControlServer::seconds_since_heartbeat() const {
    const auto now = std::chrono::duration_cast<std::chrono::nanoseconds>(SteadyClock::now().time_since_epoch()).count();
    return static_cast<double>(now - impl_->heartbeat_ns.load()) * 1e-9;
}

ControlServerCounters ControlServer::counters() const {
    std::lock_guard lk(impl_->counters_lock);
    return impl_->counters;
}

void ControlServer::adopt_socket_lock(InstanceLock lock) { impl_->socket_lock = std::move(lock); }

void ControlServer::start() {
    Impl& s = *impl_;
    const std::string path = s.o.socket_path.string();
    sockaddr_un addr = unix_address(path, "control socket");

    // One daemon per socket. Under the lock, an existing socket file is stale only if no one answers.
    if (!s.socket_lock.held()) s.socket_lock = InstanceLock::acquire(s.o.socket_path, "control socket");
    struct stat existing {};
    if (::lstat(path.c_str(), &existing) == 0) {
        if (!S_ISSOCK(existing.st_mode))
            throw UserError(fmt::format("{} exists and is not a socket; not replacing it (remove it or choose another "
                                        "[api] socket)",
                                        path));
        if (someone_answers(path))
            throw UserError(fmt::format("another process answers on {}; not replacing its socket", path));
        ::unlink(path.c_str());
    }

    const int unix_fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (unix_fd < 0) throw UserError(fmt::format("cannot create the control socket: {}", std::strerror(errno)));
    const mode_t old_mask = ::umask(0117);  // created 0660: owner and group only
    const int rc = ::bind(unix_fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
    ::umask(old_mask);
    if (rc != 0 || ::listen(unix_fd, s.o.listen_backlog) != 0) {
        const std::string why = std::strerror(errno);
        ::close(unix_fd);
        throw UserError(fmt::format("cannot listen on {}: {}", path, why));
    }
    ::chmod(path.c_str(), 0660);
    ::stat(path.c_str(), &s.bound);
    s.socket_bound = true;
    s.acceptors.push_back(std::make_unique<acceptor_t>(s.io));
    s.acceptors.back()->assign(stream(AF_UNIX, 0), unix_fd);

    if (s.o.tcp_port > 0) {
        const int tcp_fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        int one = 1;
        ::setsockopt(tcp_fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        sockaddr_in in{};
        in.sin_family = AF_INET;
        in.sin_addr.s_addr = htonl(INADDR_LOOPBACK);  // never any other interface
        in.sin_port = htons(static_cast<std::uint16_t>(s.o.tcp_port));
        if (::bind(tcp_fd, reinterpret_cast<sockaddr*>(&in), sizeof in) != 0 || ::listen(tcp_fd, s.o.listen_backlog) != 0) {
            const std::string why = std::strerror(errno);
            ::close(tcp_fd);
            throw UserError(fmt::format("cannot listen on 127.0.0.1:{}: {}", s.o.tcp_port, why));
        }
        s.acceptors.push_back(std::make_unique<acceptor_t>(s.io));
        s.acceptors.back()->assign(stream(AF_INET, IPPROTO_TCP), tcp_fd);
        s.bound_tcp_port = s.o.tcp_port;
    }

    // Leave descriptors for the drivers (reconnects), SQLite and the recorder: clients never take the last ones.
    // (getrlimit is prlimit64, which a seccomp filter may refuse: then the configured cap stands.)
    rlimit nofile{RLIM_INFINITY, RLIM_INFINITY};
    if (::getrlimit(RLIMIT_NOFILE, &nofile) != 0) nofile.rlim_cur = RLIM_INFINITY;
    const long budget = nofile.rlim_cur == RLIM_INFINITY
                            ? static_cast<long>(s.o.max_clients)
                            : static_cast<long>(nofile.rlim_cur) - count_open_fds() - 32;
    s.counters.max_clients = static_cast<std::size_t>(std::max(2L, std::min(static_cast<long>(s.o.max_clients), budget)));
    s.counters.max_clients_per_peer =
        s.o.max_clients_per_peer > 0 ? s.o.max_clients_per_peer : std::max<std::size_t>(4, s.counters.max_clients / 4);
    if (s.counters.max_clients < s.o.max_clients)
        spdlog::warn("control API: at most {} clients (api.max_clients {}), to fit the open-file limit of {}",
                     s.counters.max_clients, s.o.max_clients, nofile.rlim_cur);

    s.sweep_timer.emplace(s.io);
    s.accept_retry_timer.emplace(s.io);
    for (auto& a : s.acceptors) s.accept(*a);
    s.sweep();
    s.thread = std::thread([&s] { run_guarded("control socket", [&s] { s.io.run(); }); });
}

void ControlServer::stop() {
    Impl& s = *impl_;
    if (s.thread.joinable()) {
        s.io.stop();
        s.thread.join();
    }
    s.sessions.clear();
    s.acceptors.clear();
    // Remove the socket only if it is still the one this server bound (never a successor's).
    struct stat now {};
    if (s.socket_bound && ::stat(s.o.socket_path.c_str(), &now) == 0 && now.st_ino == s.bound.st_ino &&
        now.st_dev == s.bound.st_dev)
        ::unlink(s.o.socket_path.c_str());
    s.socket_bound = false;
    s.socket_lock = InstanceLock{};
}

}  // namespace manikind
