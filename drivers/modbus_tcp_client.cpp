#include "drivers/modbus_tcp_client.hpp"

#include <modbus/modbus.h>  // the error codes only: MODBUS_ENOBASE, EMBBADDATA

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include "protocol/modbus_tcp_frame.hpp"

namespace manikind::drivers {

namespace mtcp = protocol::modbus_tcp;

namespace {

constexpr int kPending = -1;  // a call sent and not yet answered

std::int64_t steady_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

timeval as_timeval(double seconds) {
    timeval tv{};
    tv.tv_sec = static_cast<time_t>(seconds);
    tv.tv_usec = static_cast<suseconds_t>((seconds - static_cast<double>(tv.tv_sec)) * 1e6);
    if (tv.tv_sec == 0 && tv.tv_usec == 0) tv.tv_usec = 1;  // 0 would mean "wait for ever"
    return tv;
}

// Connects one socket to one address within timeout_ms; returns 0 or errno.
int connect_within(int fd, const sockaddr* addr, socklen_t len, int timeout_ms) {
    if (::connect(fd, addr, len) == 0) return 0;
    if (errno != EINPROGRESS) return errno;
    pollfd p{fd, POLLOUT, 0};
    int rc;
    do {
        rc = ::poll(&p, 1, timeout_ms);
    } while (rc < 0 && errno == EINTR);
    if (rc == 0) return ETIMEDOUT;
    if (rc < 0) return errno;
    int err = 0;
    socklen_t el = sizeof err;
    if (::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &el) != 0) return errno;
    return err;
}

}  // namespace

std::string ModbusTcpClient::connect(const std::string& host, int port, double timeout_s) {
    close();
    timeout_s_ = timeout_s;
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_NUMERICSERV;
    addrinfo* found = nullptr;
    const std::string service = std::to_string(port);
    if (const int rc = ::getaddrinfo(host.c_str(), service.c_str(), &hints, &found); rc != 0)
        return "cannot resolve " + host + ": " + ::gai_strerror(rc);
    std::string why = "no address for " + host;
    const int timeout_ms = std::max(1, static_cast<int>(timeout_s * 1000.0));
    for (const addrinfo* a = found; a; a = a->ai_next) {
        const int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK, a->ai_protocol);
        if (fd < 0) {
            why = std::strerror(errno);
            continue;
        }
        if (const int err = connect_within(fd, a->ai_addr, a->ai_addrlen, timeout_ms); err != 0) {
            why = std::strerror(err);
            ::close(fd);
            continue;
        }
        // Blocking from here: a reply is waited for inside recv, bounded by SO_RCVTIMEO, with no
        // poll or select before it.
        const int flags = ::fcntl(fd, F_GETFL);
        ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
        const int one = 1;
        ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);  // a request is one small segment: send it now
        const timeval tv = as_timeval(timeout_s);
        ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
        ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
        fd_ = fd;
        why.clear();
        break;
    }
    ::freeaddrinfo(found);
    in_.clear();
    return why;
}

void ModbusTcpClient::close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    in_.clear();
}

// The first call not answered takes the error; the others were lost with the connection.
void ModbusTcpClient::fail_pending(std::span<Call> calls, int err) {
    for (auto& c : calls)
        if (c.err == kPending) {
            c.err = err;
            err = ENOTCONN;
        }
    close();
}

// The first wait of a transaction is the blocking recv itself (SO_RCVTIMEO is the whole reply
// timeout); a reply that comes in pieces waits for the rest in poll, for what is left of it.
int ModbusTcpClient::receive_some(bool first, std::int64_t deadline_ns) {
    int flags = 0;
    if (!first) {
        const std::int64_t left_ns = deadline_ns - steady_ns();
        if (left_ns <= 0) return -ETIMEDOUT;
        pollfd p{fd_, POLLIN, 0};
        const int rc = ::poll(&p, 1, static_cast<int>((left_ns + 999'999) / 1'000'000));
        if (rc == 0) return -ETIMEDOUT;
        if (rc < 0) return errno == EINTR ? 0 : -errno;
        flags = MSG_DONTWAIT;
    }
    const std::size_t old = in_.size();
    in_.resize(old + 2048);
    const ssize_t got = ::recv(fd_, in_.data() + old, 2048, flags);
    in_.resize(old + static_cast<std::size_t>(got > 0 ? got : 0));
    if (got > 0) return static_cast<int>(got);
    if (got == 0) return -ECONNRESET;  // the device closed the connection
    if (errno == EAGAIN || errno == EWOULDBLOCK) return first ? -ETIMEDOUT : 0;
    if (errno == EINTR) return 0;
    return -errno;
}

void ModbusTcpClient::transact(std::span<Call> calls) {
    if (calls.empty()) return;
    out_.clear();
    for (auto& c : calls) {
        c.request.transaction = next_transaction_++;
        c.err = kPending;
        c.words.clear();
        c.why.clear();
        mtcp::append_request(out_, c.request);
    }
    if (fd_ < 0) return fail_pending(calls, ENOTCONN);
    const std::int64_t deadline_ns = steady_ns() + static_cast<std::int64_t>(timeout_s_ * 1e9);
    for (std::size_t sent = 0; sent < out_.size();) {
        const ssize_t n = ::send(fd_, out_.data() + sent, out_.size() - sent, MSG_NOSIGNAL);
        if (n < 0) {
            if (errno == EINTR) continue;
            return fail_pending(calls, errno == EAGAIN || errno == EWOULDBLOCK ? ETIMEDOUT : errno);
        }
        sent += static_cast<std::size_t>(n);
    }
    if (sent_hook_) sent_hook_(fd_, calls.size(), deadline_ns);
    std::size_t pending = calls.size();
    bool first = true;
    while (pending > 0) {
        const int got = receive_some(first, deadline_ns);
        first = false;
        if (got < 0) return fail_pending(calls, -got);
        // Every whole reply received so far, paired with its request by transaction id.
        std::size_t used = 0;
        for (;;) {
            const auto frame = mtcp::first_frame(in_.data() + used, in_.size() - used);
            if (frame.state == mtcp::FrameState::need_more) break;
            const std::span<const std::uint8_t> adu(in_.data() + used, frame.size);
            Call* call = nullptr;
            if (frame.state == mtcp::FrameState::complete)
                for (auto& c : calls)
                    if (c.err == kPending && c.request.transaction == mtcp::transaction_of(adu)) call = &c;
            if (!call) {
                // Bytes that are no reply to anything in flight: the stream is lost.
                for (auto& c : calls)
                    if (c.err == kPending) {
                        c.why = frame.state == mtcp::FrameState::malformed ? "a reply's header is malformed"
                                                                            : "a reply answers no request in flight";
                        break;
                    }
                return fail_pending(calls, EMBBADDATA);
            }
            auto reply = mtcp::check_reply(adu, call->request);
            used += frame.size;
            --pending;
            if (reply.state == mtcp::ReplyState::ok) {
                call->err = 0;
                call->words = std::move(reply.words);
            } else if (reply.state == mtcp::ReplyState::exception) {
                call->err = MODBUS_ENOBASE + reply.exception_code;
            } else {
                call->err = EMBBADDATA;
                call->why = std::move(reply.why);
                return fail_pending(calls, ENOTCONN);
            }
        }
        in_.erase(in_.begin(), in_.begin() + static_cast<std::ptrdiff_t>(used));
    }
    // Bytes past the last reply answer nothing sent: the next transaction finds them and closes.
}

}  // namespace manikind::drivers
