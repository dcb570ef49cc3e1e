#include "sim/devices/modbus_server.hpp"

#include <cstdio>
#include <arpa/inet.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <vector>
#include <stdexcept>

#include "protocol/modbus_tcp_frame.hpp"

namespace manikind::sim {

namespace mr = protocol::modbus_registers;
namespace mtcp = protocol::modbus_tcp;
constexpr std::size_t kMinRequestBytes = 12;  // MBAP (7), function, address (2), count or value (2)

namespace {
modbus_mapping_t* as_mapping(void* p) { return static_cast<modbus_mapping_t*>(p); }
modbus_t* as_ctx(void* p) { return static_cast<modbus_t*>(p); }
}  // namespace

VirtualModbusServer::VirtualModbusServer(std::string name, std::vector<ServedRegister> registers,
                                         std::mutex& world_lock)
    : name_(std::move(name)), registers_(std::move(registers)), world_lock_(world_lock) {
    std::map<int, int> size_per_unit;
    for (const auto& r : registers_) {
        int& n = size_per_unit[r.unit_id];
        n = std::max(n, r.spec.address + mr::register_count(r.spec.type));
    }
    for (const auto& [unit, n] : size_per_unit) mappings_[unit] = modbus_mapping_new(0, 0, n, 0);
    // Each register encoded for the image: limits are the client's to respect. Made once, not
    // copied (with its name) at every request.
    for (const auto& r : registers_) {
        auto spec = r.spec;
        spec.writable = true;
        spec.min_value = -1e300;
        spec.max_value = 1e300;
        image_specs_.push_back(std::move(spec));
    }
}

VirtualModbusServer::~VirtualModbusServer() {
    stop();
    for (auto& [unit, m] : mappings_) modbus_mapping_free(as_mapping(m));
}

std::vector<int> VirtualModbusServer::unit_ids() const {
    std::vector<int> ids;
    for (const auto& [unit, m] : mappings_) ids.push_back(unit);
    return ids;
}

void VirtualModbusServer::start(int port) {
    ctx_ = modbus_new_tcp("127.0.0.1", port);
    if (!ctx_) throw std::runtime_error(name_ + ": modbus_new_tcp failed");
    listen_fd_ = modbus_tcp_listen(as_ctx(ctx_), 8);
    if (listen_fd_ < 0)
        throw std::runtime_error(name_ + ": cannot listen on 127.0.0.1:" + std::to_string(port) + ": " +
                                 modbus_strerror(errno));
    sockaddr_in addr{};
    socklen_t len = sizeof addr;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    if (::pipe(wake_pipe_) != 0) throw std::runtime_error(name_ + ": pipe failed");
    on_caller_ = false;
    start_thread();
}

void VirtualModbusServer::start_thread() {
    stopping_ = false;
    // A simulated device outlives a bad request: what escapes serve() is reported and it serves on.
    thread_ = std::thread([this] {
        for (;;) {
            try {
                serve();
                return;
            } catch (const std::exception& e) {
                std::fprintf(stderr, "%s: simulated Modbus server: %s; serving on\n", name_.c_str(), e.what());
            }
        }
    });
}

void VirtualModbusServer::stop_thread() {
    if (!thread_.joinable()) return;
    stopping_ = true;
    const char b = 'x';
    [[maybe_unused]] auto n = ::write(wake_pipe_[1], &b, 1);
    thread_.join();
    char drained = 0;  // the one byte written above: caller mode must not see a stale wake
    [[maybe_unused]] auto r = ::read(wake_pipe_[0], &drained, 1);
}

void VirtualModbusServer::serve_on_caller() {
    if (on_caller_ || !ctx_) return;
    stop_thread();
    on_caller_ = true;
}

void VirtualModbusServer::serve_on_own_thread() {
    if (!on_caller_ || !ctx_) return;
    std::lock_guard lk(serve_lock_);  // no serve_until under way
    on_caller_ = false;
    start_thread();
}

void VirtualModbusServer::stop() {
    if (!ctx_) return;
    stop_thread();
    on_caller_ = false;
    for (const auto& [c, pending] : clients_) ::close(c);
    clients_.clear();
    ::close(wake_pipe_[0]);
    ::close(wake_pipe_[1]);
    ::close(listen_fd_);
    modbus_free(as_ctx(ctx_));
    ctx_ = nullptr;
}

void VirtualModbusServer::set_faults(const ModbusFaults& f) {
    std::lock_guard lk(faults_lock_);
    if (f.stuck && !faults_.stuck) {
        std::lock_guard wl(world_lock_);
        frozen_.clear();
        for (const auto& r : registers_) frozen_[r.spec.name] = r.read();
    }
    faults_ = f;
}

ModbusFaults VirtualModbusServer::faults() const {
    std::lock_guard lk(faults_lock_);
    return faults_;
}

// Encodes the world's current values into the unit's register image.
void VirtualModbusServer::refresh(int unit) {
    auto* m = as_mapping(mappings_.at(unit));
    const ModbusFaults f = faults();
    std::lock_guard wl(world_lock_);
    for (const auto& r : registers_) {
        if (r.unit_id != unit) continue;
        double v = f.stuck && frozen_.count(r.spec.name) ? frozen_.at(r.spec.name) : r.read();
        if (r.probe) v = r.probe->to_raw(v);
        std::vector<std::uint16_t> words;
        try {
            words = mr::encode(image_specs_[static_cast<std::size_t>(&r - registers_.data())], v);
        } catch (const std::exception&) {
            continue;  // out of the raw type's range: the image keeps the last value
        }
        for (std::size_t i = 0; i < words.size(); ++i)
            m->tab_registers[static_cast<std::size_t>(r.spec.address) + i] = words[i];
    }
}

// Function 06 / 16 to a mapped register: decode, check limits, hand to the world. Returns false
// (and the caller answers ILLEGAL DATA VALUE) when refused.
bool VirtualModbusServer::handle_write(int unit, const std::uint8_t* q, int length, int h) {
    const int function = q[h];
    if (function != MODBUS_FC_WRITE_SINGLE_REGISTER && function != MODBUS_FC_WRITE_MULTIPLE_REGISTERS) return true;
    const int address = (q[h + 1] << 8) | q[h + 2];
    std::vector<std::uint16_t> words;
    if (function == MODBUS_FC_WRITE_SINGLE_REGISTER) {
        words.push_back(static_cast<std::uint16_t>((q[h + 3] << 8) | q[h + 4]));
    } else {
        const int count = (q[h + 3] << 8) | q[h + 4];
        for (int i = 0; i < count && h + 6 + 2 * i + 1 < length; ++i)
            words.push_back(static_cast<std::uint16_t>((q[h + 6 + 2 * i] << 8) | q[h + 7 + 2 * i]));
    }
    for (const auto& r : registers_) {
        if (r.unit_id != unit || r.spec.address != address) continue;
        if (!r.write) return false;  // read-only parameter
        if (static_cast<int>(words.size()) < mr::register_count(r.spec.type)) return false;
        const double v = mr::decode(r.spec, words);
        if (v < r.spec.min_value || v > r.spec.max_value || !std::isfinite(v)) return false;
        std::lock_guard wl(world_lock_);
        return r.write(v);
    }
    return true;  // unmapped: libmodbus answers ILLEGAL DATA ADDRESS if out of the image
}

// Answers one whole request from client c; false: the connection is to be dropped.
bool VirtualModbusServer::answer(int c, std::uint8_t* query, int length) {
    ++requests_;
    const ModbusFaults f = faults();
    if (f.drop) return false;
    if (f.silent) return true;
    modbus_t* ctx = as_ctx(ctx_);
    const int header = modbus_get_header_length(ctx);
    modbus_set_socket(ctx, c);
    const int unit = query[static_cast<std::size_t>(header - 1)];
    if (f.exception) {
        modbus_reply_exception(ctx, query, MODBUS_EXCEPTION_SLAVE_OR_SERVER_FAILURE);
    } else if (!mappings_.count(unit)) {
        modbus_reply_exception(ctx, query, MODBUS_EXCEPTION_GATEWAY_TARGET);
    } else {
        refresh(unit);
        if (!handle_write(unit, query, length, header))
            modbus_reply_exception(ctx, query, MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE);
        else
            modbus_reply(ctx, query, length, as_mapping(mappings_.at(unit)));
    }
    return true;
}

void VirtualModbusServer::serve() {
    while (!stopping_ && serve_round(-1, -1, nullptr)) {
    }
}

VirtualModbusServer::Served VirtualModbusServer::serve_until(int client_fd, std::uint64_t requests, std::int64_t deadline_ns) {
    std::lock_guard lk(serve_lock_);
    Served out;
    if (!on_caller_) return out;  // the own thread answers
    const std::uint64_t before = requests_.load();
    for (;;) {
        const std::int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::steady_clock::now().time_since_epoch()).count();
        const std::int64_t left_ns = deadline_ns - now_ns;
        try {
            // The request is almost always there already (loopback delivers within the client's
            // send): read the connections first, and wait in select only when none had anything.
            if (!serve_clients(nullptr))
                serve_round(left_ns > 0 ? static_cast<int>((left_ns + 999'999) / 1'000'000) : 0, client_fd, &out.reply_waiting);
        } catch (const std::exception& e) {
            // As on its own thread: a bad request is reported and the device serves on.
            std::fprintf(stderr, "%s: simulated Modbus server: %s; serving on\n", name_.c_str(), e.what());
        }
        out.answered = requests_.load() - before;
        out.deadline_passed = left_ns <= 0;
        if (out.answered >= requests || out.reply_waiting || out.deadline_passed) return out;
    }
}

bool VirtualModbusServer::serve_round(int timeout_ms, int also_fd, bool* also_ready) {
    // Each client's bytes not yet a whole request (clients_). A request is read in one recv from
    // what the socket holds and cut into ADUs here (protocol/modbus_tcp_frame.hpp); libmodbus's
    // own receive waited in select before the header and again before the rest (3 selects and 2
    // reads per request on top of this loop's select; now 1 and 1). libmodbus still builds every
    // reply.
    fd_set fds;
    FD_ZERO(&fds);
    FD_SET(listen_fd_, &fds);
    FD_SET(wake_pipe_[0], &fds);
    int max_fd = std::max(listen_fd_, wake_pipe_[0]);
    for (const auto& [c, pending] : clients_) {
        FD_SET(c, &fds);
        max_fd = std::max(max_fd, c);
    }
    if (also_fd >= 0 && also_fd < FD_SETSIZE) {
        FD_SET(also_fd, &fds);
        max_fd = std::max(max_fd, also_fd);
    }
    timeval tv{timeout_ms / 1000, (timeout_ms % 1000) * 1000};
    if (::select(max_fd + 1, &fds, nullptr, nullptr, timeout_ms >= 0 ? &tv : nullptr) < 0) return errno == EINTR;
    if (FD_ISSET(wake_pipe_[0], &fds)) return false;
    if (also_ready && also_fd >= 0 && also_fd < FD_SETSIZE && FD_ISSET(also_fd, &fds)) *also_ready = true;
    if (FD_ISSET(listen_fd_, &fds)) {
        const int c = ::accept(listen_fd_, nullptr, nullptr);
        if (c >= 0 && c >= FD_SETSIZE) {
            ::close(c);  // select cannot watch it; the client sees its connection closed
        } else if (c >= 0) {
            // Replies go out at once: with Nagle's algorithm the second reply to two
            // pipelined requests waits for the client's delayed ACK of the first (40 ms).
            const int one = 1;
            ::setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
            clients_.emplace(c, std::vector<std::uint8_t>{});
        }
    }
    serve_clients(&fds);
    return true;
}

bool VirtualModbusServer::serve_clients(const fd_set* readable) {
    bool received = false;
    for (auto it = clients_.begin(); it != clients_.end();) {
        const int c = it->first;
        auto& pending = it->second;
        bool keep = true;
        if (!readable || FD_ISSET(c, readable)) {
            std::uint8_t chunk[mtcp::kMaxAduBytes * 4];
            const ssize_t got = ::recv(c, chunk, sizeof chunk, MSG_DONTWAIT);
            if (got == 0 || (got < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) keep = false;
            if (got > 0) pending.insert(pending.end(), chunk, chunk + got);
            received = received || got > 0;
        }
        // Every whole request in what arrived, in order; a malformed one drops the connection
        // as a device would (libmodbus's receive did the same). Requests that came together
        // (a client's pipelined poll) are answered in one segment: corked while libmodbus sends
        // each reply, so the loopback transmits once and the client wakes once.
        std::size_t used = 0;
        const bool several = keep && [&] {
            const auto f = mtcp::first_frame(pending.data(), pending.size());
            return f.state == mtcp::FrameState::complete && pending.size() > f.size;
        }();
        const int cork_on = 1, cork_off = 0;
        if (several) ::setsockopt(c, IPPROTO_TCP, TCP_CORK, &cork_on, sizeof cork_on);
        while (keep) {
            const auto frame = mtcp::first_frame(pending.data() + used, pending.size() - used);
            if (frame.state == mtcp::FrameState::need_more) break;
            if (frame.state == mtcp::FrameState::malformed) {
                keep = false;
                break;
            }
            // Every function a device here serves carries an address and a count or value
            // after its code (12 bytes at least); a shorter request is malformed (libmodbus's
            // receive read as many bytes as the function needs, whatever the length said).
            if (frame.size < kMinRequestBytes) {
                keep = false;
                break;
            }
            // Answered from a zeroed buffer of the largest ADU: libmodbus and handle_write read
            // the fields a function has, and a request whose counts claim more than it holds
            // reads zeros there, never past its own bytes.
            std::array<std::uint8_t, mtcp::kMaxAduBytes> query{};
            std::copy_n(pending.data() + used, frame.size, query.begin());
            keep = answer(c, query.data(), static_cast<int>(frame.size));
            used += frame.size;
        }
        if (several) ::setsockopt(c, IPPROTO_TCP, TCP_CORK, &cork_off, sizeof cork_off);
        pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(std::min(used, pending.size())));
        if (!keep) {
            ::close(c);
            it = clients_.erase(it);
        } else {
            ++it;
        }
    }
    return received;
}

}  // namespace manikind::sim
