#include "drivers/manikin_can_driver.hpp"

#include <fmt/format.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>

#include <linux/can/raw.h>

namespace manikind::drivers {

namespace mc = protocol::manikin_can;

int open_socketcan(const std::string& interface, std::string& error) {
    const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
    if (fd < 0) {
        error = std::string("socket(PF_CAN): ") + std::strerror(errno) + " (no SocketCAN in this kernel?)";
        return -1;
    }
    // Error frames too: bus-off and controller problems must reach the driver.
    can_err_mask_t err_mask = CAN_ERR_MASK;
    ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask);
    ifreq ifr{};
    std::snprintf(ifr.ifr_name, IFNAMSIZ, "%s", interface.c_str());
    if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
        error = "no CAN interface " + interface + ": " + std::strerror(errno);
        ::close(fd);
        return -1;
    }
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
        error = "bind " + interface + ": " + std::strerror(errno);
        ::close(fd);
        return -1;
    }
    return fd;
}

ManikinCanDriver::ManikinCanDriver(boost::asio::io_context& io, int fd, ManikinBusOptions options,
                                   const Clock& clock, SampleSink sink)
    : io_(io), options_(std::move(options)), clock_(clock), sink_(std::move(sink)) {
    status_.name = options_.device_name;
    status_.transport = fd >= 0 ? "socketcan " + options_.interface : "replay";
    status_.last_error = options_.open_error;
    if (fd >= 0) stream_ = std::make_unique<boost::asio::posix::stream_descriptor>(io_, fd);
}

ManikinCanDriver::~ManikinCanDriver() {
    *alive_ = false;
    stop();
}

void ManikinCanDriver::start() {
    std::lock_guard lk(lock_);
    status_.connected = stream_ != nullptr;
    status_.last_good_mono_ns = clock_.mono_ns();
    if (stream_) start_read();
}

void ManikinCanDriver::stop() {
    if (stream_) {
        boost::system::error_code ignored;
        stream_->cancel(ignored);
        stream_->close(ignored);
        stream_.reset();
    }
    std::lock_guard lk(lock_);
    status_.connected = false;
}

void ManikinCanDriver::start_read() {
    // Wait for readiness, then read every frame waiting with recvmmsg. Not async_read_some: asio
    // tries that read at once, before waiting, and on a bus that just went quiet it returned
    // EAGAIN at every frame burst (80 % of the demo's recvmmsg calls, issue 36).
    stream_->async_wait(boost::asio::posix::stream_descriptor::wait_read,
                        [this, alive = alive_](const boost::system::error_code& ec) {
        if (!*alive) return;
        if (ec) {
            if (ec == boost::asio::error::operation_aborted) return;
            std::lock_guard lk(lock_);
            status_.connected = false;
            ++status_.comm_errors;
            status_.last_error = "read: " + ec.message();
            return;  // a socketpair or CAN socket that fails stays down; the daemon reports it
        }
        if (stream_ && drain_waiting() && stream_) start_read();
    });
}

void ManikinCanDriver::take(const can_frame& frame, std::size_t bytes) {
    if (bytes == sizeof(can_frame) || bytes == CAN_MTU) {
        ingest(frame);
    } else {
        std::lock_guard lk(lock_);
        ++status_.malformed;
        status_.last_error = fmt::format("a read of {} bytes, not one CAN frame", bytes);
    }
}

bool ManikinCanDriver::drain_waiting() {
    constexpr unsigned batch = 64;
    std::array<can_frame, batch> frames;
    std::array<iovec, batch> iov;
    std::array<mmsghdr, batch> msgs;
    for (;;) {
        if (!stream_) return false;  // a sink stopped the driver while it took the frames before
        for (unsigned i = 0; i < batch; ++i) {
            iov[i] = {&frames[i], sizeof(can_frame)};
            msgs[i] = {};
            msgs[i].msg_hdr.msg_iov = &iov[i];
            msgs[i].msg_hdr.msg_iovlen = 1;
        }
        const int n = ::recvmmsg(stream_->native_handle(), msgs.data(), batch, MSG_DONTWAIT, nullptr);
        if (n < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN || errno == EWOULDBLOCK) return true;
            std::lock_guard lk(lock_);
            status_.connected = false;
            ++status_.comm_errors;
            status_.last_error = std::string("read: ") + std::strerror(errno);
            return false;
        }
        if (n == 0) {  // readable and nothing to read: the peer closed
            std::lock_guard lk(lock_);
            status_.connected = false;
            ++status_.comm_errors;
            status_.last_error = "read: End of file";
            return false;
        }
        for (int i = 0; i < n; ++i) {
            const auto& m = msgs[static_cast<std::size_t>(i)];
            if (m.msg_len == 0) {  // the peer closed (a read would have returned 0: end of file)
                std::lock_guard lk(lock_);
                status_.connected = false;
                ++status_.comm_errors;
                status_.last_error = "read: End of file";
                return false;
            }
            take(frames[static_cast<std::size_t>(i)], m.msg_len);
        }
        if (static_cast<unsigned>(n) < batch) return true;  // drained: fewer than asked for
    }
}

void ManikinCanDriver::emit(const std::string& channel, double value, Quality q, std::int64_t mono,
                            std::int64_t utc) {
    sink_(Sample{options_.device_name, channel, value, q, mono, utc});
}

void ManikinCanDriver::ingest(const can_frame& frame) {
    ++frames_received_;
    capture(frame);
    const std::int64_t mono = clock_.mono_ns(), utc = clock_.utc_ns();
    auto decoded = mc::decode(frame);
    if (auto* err = std::get_if<mc::DecodeError>(&decoded)) {
        std::lock_guard lk(lock_);
        ++status_.malformed;
        status_.last_error = err->reason;
        return;
    }
    const auto& msg = std::get<mc::Message>(decoded);
    if (const auto* z = std::get_if<mc::ZoneStatus>(&msg)) {
        const bool sensor_bad = (z->flags & mc::sensor_fault) != 0;
        const bool heater_bad = (z->flags & (mc::heater_fault | mc::over_temperature)) != 0;
        {
            std::lock_guard lk(lock_);
            ++status_.frames;
            status_.samples += 4;
            status_.stale = false;
            status_.last_good_mono_ns = mono;
            if (sensor_bad || heater_bad) {
                ++status_.device_faults;
                status_.last_error = fmt::format("zone {} reports {}{}", z->zone, sensor_bad ? "sensor fault " : "",
                                                 heater_bad ? "heater fault" : "");
            }
        }
        // The zone's four channel names, made once (35 zones x 4 readings a step otherwise built
        // a name and its copy each).
        auto [names, fresh] = zone_channels_.try_emplace(z->zone);
        if (fresh) {
            const std::string prefix = fmt::format("z{:02d}.", z->zone);
            names->second = {prefix + "skin_temp_c", prefix + "heat_flux_w_m2", prefix + "heater_power_w_m2",
                             prefix + "sweat_rate_g_m2_h"};
        }
        const auto& channel = names->second;
        const bool too_hot = z->skin_temp_c > options_.max_skin_temp_c;
        emit(channel[0], z->skin_temp_c, sensor_bad || too_hot ? Quality::out_of_range : Quality::good, mono, utc);
        const Quality hq = heater_bad ? Quality::out_of_range : Quality::good;
        emit(channel[1], z->heat_flux_w_m2, hq, mono, utc);
        emit(channel[2], z->heater_power_w_m2, hq, mono, utc);
        emit(channel[3], z->sweat_rate_g_m2_h, Quality::good, mono, utc);
    } else if (const auto* hb = std::get_if<mc::Heartbeat>(&msg)) {
        std::lock_guard lk(lock_);
        if (heartbeat_ && static_cast<std::uint8_t>(heartbeat_->sequence + 1) != hb->sequence) {
            ++status_.malformed;
            status_.last_error = fmt::format("heartbeat sequence jumped from {} to {} (frames lost)", heartbeat_->sequence, hb->sequence);
        }
        if (hb->error_bits != 0 && (!heartbeat_ || heartbeat_->error_bits == 0)) {
            ++status_.device_faults;
            status_.last_error = fmt::format("manikin error bits 0x{:04x}", hb->error_bits);
        }
        heartbeat_ = *hb;
        ++status_.frames;
        status_.stale = false;
        status_.last_good_mono_ns = mono;
    } else if (const auto* be = std::get_if<mc::BusError>(&msg)) {
        std::lock_guard lk(lock_);
        ++status_.comm_errors;
        if (be->bus_off) ++status_.device_faults;
        status_.last_error = be->bus_off ? "CAN bus-off" : fmt::format("CAN error frame class 0x{:x}", be->error_class);
    }
    // Setpoint and Control frames are the host's own (seen on a real bus as echoes): nothing to do.
}

std::optional<mc::Heartbeat> ManikinCanDriver::last_heartbeat() const {
    std::lock_guard lk(lock_);
    return heartbeat_;
}

bool ManikinCanDriver::write_frame(const can_frame& frame) {
    if (!stream_) return false;
    boost::system::error_code ec;
    stream_->write_some(boost::asio::buffer(&frame, sizeof frame), ec);
    if (ec) {
        std::lock_guard lk(lock_);
        ++status_.comm_errors;
        status_.last_error = "write: " + ec.message();
        return false;
    }
    capture(frame);
    return true;
}

bool ManikinCanDriver::send(const mc::Setpoint& setpoint) { return write_frame(mc::encode(setpoint)); }

bool ManikinCanDriver::set_run(bool run) {
    run_ = run;
    return write_frame(mc::encode(mc::Control{run_, host_heartbeat_}));
}

void ManikinCanDriver::check(std::int64_t now_mono_ns) {
    // Host heartbeat: the manikin's watchdog stops heating when this stalls.
    ++host_heartbeat_;
    write_frame(mc::encode(mc::Control{run_, host_heartbeat_}));
    std::lock_guard lk(lock_);
    const auto limit_ns = static_cast<std::int64_t>(options_.stale_after_s * 1e9);
    if (status_.last_good_mono_ns >= 0 && now_mono_ns - status_.last_good_mono_ns > limit_ns) {
        if (!status_.stale) {
            ++status_.timeouts;
            // What came before (a bus-off, an error frame) stays said: it is likely the cause.
            const std::string before = status_.last_error;
            status_.last_error = fmt::format("no good frame for more than {} s", options_.stale_after_s);
            if (!before.empty() && before.rfind("no good frame", 0) != 0) status_.last_error += "; before that: " + before;
        }
        status_.stale = true;
    }
}

DriverStatus ManikinCanDriver::status() const {
    std::lock_guard lk(lock_);
    return status_;
}

void ManikinCanDriver::capture_to(const std::string& path) {
    capture_.open(path, std::ios::app);
    if (!capture_) {
        std::lock_guard lk(lock_);
        status_.last_error = "cannot open capture file " + path;
    }
}

void ManikinCanDriver::capture(const can_frame& frame) {
    if (!capture_.is_open()) return;
    capture_ << mc::to_candump_line(frame, static_cast<double>(clock_.utc_ns()) * 1e-9, options_.interface) << '\n';
}

}  // namespace manikind::drivers
