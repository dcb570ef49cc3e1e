#include "drivers/serial_line_driver.hpp"

#include <boost/asio/serial_port.hpp>
#include <boost/asio/write.hpp>
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <fmt/core.h>

namespace manikind::drivers {

SerialLineDriver::SerialLineDriver(boost::asio::io_context& io, SerialOptions options, const Clock& clock,
                                   SampleSink sink)
    : clock_(clock), io_(io), options_(std::move(options)), sink_(std::move(sink)) {
    status_.name = options_.device_name;
    status_.transport = "serial " + options_.path;
}

SerialLineDriver::~SerialLineDriver() {
    *alive_ = false;
    stop();
}

void SerialLineDriver::start() {
    running_ = true;
    if (!open_port()) backoff_.failed(clock_.mono_ns());
}

void SerialLineDriver::release_port() {
    if (!port_) return;
    boost::system::error_code ignored;
    port_->close(ignored);
    port_.reset();
}

void SerialLineDriver::stop() {
    running_ = false;
    release_port();
    std::lock_guard lk(lock_);
    status_.connected = false;
}

bool SerialLineDriver::open_port() {
    auto port = std::make_unique<boost::asio::serial_port>(io_);
    boost::system::error_code ec;
    port->open(options_.path, ec);
    if (!ec) port->set_option(boost::asio::serial_port_base::baud_rate(options_.baud), ec);
    if (!ec) port->set_option(boost::asio::serial_port_base::character_size(8), ec);
    if (!ec) port->set_option(boost::asio::serial_port_base::parity(boost::asio::serial_port_base::parity::none), ec);
    if (!ec) port->set_option(boost::asio::serial_port_base::stop_bits(boost::asio::serial_port_base::stop_bits::one), ec);
    // Set up, the port is read as a plain descriptor (the header says why).
    std::unique_ptr<boost::asio::posix::stream_descriptor> line;
    if (!ec) {
        const int fd = ::fcntl(port->native_handle(), F_DUPFD_CLOEXEC, 0);  // not inherited, as asio opened it
        if (fd < 0) ec.assign(errno, boost::system::system_category());
        boost::system::error_code ignored;
        port->close(ignored);
        if (!ec) {
            line = std::make_unique<boost::asio::posix::stream_descriptor>(io_, fd);
            line->non_blocking(true, ec);
        }
    }
    std::lock_guard lk(lock_);
    if (ec) {
        ++status_.comm_errors;
        status_.last_error = "open " + options_.path + ": " + ec.message();
        return false;
    }
    port_ = std::move(line);
    if (ever_connected_) ++status_.reconnects;
    ever_connected_ = true;
    status_.connected = true;
    // A fresh connection starts the silence clock, so a device that never speaks goes stale.
    status_.last_good_mono_ns = clock_.mono_ns();
    start_read();
    return true;
}

void SerialLineDriver::start_read() {
    port_->async_wait(boost::asio::posix::stream_descriptor::wait_read, [this, alive = alive_](const boost::system::error_code& ec) {
        if (!*alive) return;
        if (ec) {
            if (ec == boost::asio::error::operation_aborted) return;
            close_port(ec.message());
            return;
        }
        if (read_waiting() && port_) start_read();
    });
}

bool SerialLineDriver::read_waiting() {
    // What arrived, in reads of the buffer's size; a read that fills it may have left more.
    for (;;) {
        if (!port_) return false;  // the parser's sink stopped the driver
        const ssize_t n = ::read(port_->native_handle(), buffer_.data(), buffer_.size());
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) return true;  // a wake with nothing after all
        if (n <= 0) {  // a hang-up (pty closed, adapter unplugged): as asio's read said it
            close_port(n == 0 ? boost::system::error_code(boost::asio::error::eof).message()
                              : boost::system::error_code(errno, boost::system::system_category()).message());
            return false;
        }
        bytes_received_ += static_cast<std::uint64_t>(n);
        on_bytes(buffer_.data(), static_cast<std::size_t>(n));
        if (static_cast<std::size_t>(n) < buffer_.size()) return true;
    }
}

void SerialLineDriver::close_port(const std::string& why) {
    release_port();
    {
        std::lock_guard lk(lock_);
        status_.connected = false;
        ++status_.comm_errors;
        status_.last_error = "read " + options_.path + ": " + why;
    }
    emit_degraded(Quality::comm_error);
    backoff_.failed(clock_.mono_ns());
}

void SerialLineDriver::check(std::int64_t now_mono_ns) {
    if (!running_) return;
    if (!port_) {
        if (backoff_.due(now_mono_ns)) {
            if (open_port()) backoff_.reset();
            else backoff_.failed(now_mono_ns);
        }
        return;
    }
    bool went_stale = false;
    {
        std::lock_guard lk(lock_);
        const auto limit_ns = static_cast<std::int64_t>(options_.stale_after_s * 1e9);
        if (status_.last_good_mono_ns >= 0 && now_mono_ns - status_.last_good_mono_ns > limit_ns) {
            if (!status_.stale) {
                ++status_.timeouts;
                const std::string before = status_.last_error;
                status_.last_error = fmt::format("no good line for more than {} s", options_.stale_after_s);
                if (!before.empty() && before.rfind("no good line", 0) != 0) status_.last_error += "; before that: " + before;
            }
            status_.stale = true;
            went_stale = true;
        }
    }
    if (went_stale) emit_degraded(Quality::stale);
}

DriverStatus SerialLineDriver::status() const {
    std::lock_guard lk(lock_);
    return status_;
}

bool SerialLineDriver::send(const std::string& bytes) {
    if (!port_) return false;
    boost::system::error_code ec;
    boost::asio::write(*port_, boost::asio::buffer(bytes), ec);
    if (ec) {
        std::lock_guard lk(lock_);
        ++status_.comm_errors;
        status_.last_error = "write: " + ec.message();
        return false;
    }
    return true;
}

void SerialLineDriver::emit(const std::string& channel, double value, Quality quality) {
    if (quality == Quality::good) {
        std::lock_guard lk(lock_);
        ++status_.samples;
    }
    sink_(Sample{options_.device_name, channel, value, quality, clock_.mono_ns(), clock_.utc_ns()});
}

void SerialLineDriver::note_good_frame() {
    ++status_.frames;
    status_.stale = false;
    status_.last_good_mono_ns = clock_.mono_ns();
}

}  // namespace manikind::drivers
