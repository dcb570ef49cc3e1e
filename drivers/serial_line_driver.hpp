#pragma once
// Base for the serial instruments (WindSonic, CSAT3B): the port opened and set up (baud, 8N1) by
// a Boost.Asio serial_port, then read on the shared io_context as a descriptor: wait for
// readiness, read whatever arrived, hand the bytes to a codec's parser (serial_port's own read
// tries the read before waiting, and Boost 1.74's serial_port cannot wait: on a line that had
// just gone quiet that was a read returning EAGAIN at every burst, 4 per step of the demo). The same code
// reads a USB/RS-232 adapter on a lab PC and a pseudo-terminal of the simulated lab. A read error
// (adapter unplugged, pty hung up) closes the port; check() re-opens it with backoff. Silence
// longer than `stale_after_s` marks the device stale and is counted as a timeout.
#include <boost/asio/io_context.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "drivers/driver.hpp"

namespace manikind::drivers {

struct SerialOptions {
    std::string device_name;         // "windsonic"
    std::string path;                // /dev/ttyUSB0, /dev/serial/by-id/..., or a pty path
    unsigned baud = 9600;
    double stale_after_s = 3.0;
};

class SerialLineDriver : public Driver {
public:
    SerialLineDriver(boost::asio::io_context& io, SerialOptions options, const Clock& clock, SampleSink sink);
    ~SerialLineDriver() override;

    const std::string& name() const override { return options_.device_name; }
    void start() override;
    void stop() override;
    void check(std::int64_t now_mono_ns) override;
    DriverStatus status() const override;

    // Sends bytes to the instrument (polled mode, configuration commands). False when closed.
    bool send(const std::string& bytes);
    // Bytes read so far: the simulated lab's lockstep waits until it equals what it wrote.
    std::uint64_t bytes_received() const { return bytes_received_.load(); }

protected:
    // Feeds the codec; returns nothing: the subclass emits samples and updates counters.
    virtual void on_bytes(const std::uint8_t* data, std::size_t n) = 0;
    // Emits the last values again with the given quality (stale or comm_error) during silence.
    virtual void emit_degraded(Quality quality) = 0;

    void emit(const std::string& channel, double value, Quality quality);
    void note_good_frame();  // call under lock_ from on_bytes
    const Clock& clock_;
    mutable std::mutex lock_;
    DriverStatus status_;

private:
    bool open_port();
    void start_read();
    bool read_waiting();  // false when the port was closed
    void close_port(const std::string& why);  // after a read error: counted, degraded, retried
    void release_port();

    boost::asio::io_context& io_;
    SerialOptions options_;
    SampleSink sink_;
    std::unique_ptr<boost::asio::posix::stream_descriptor> port_;
    std::array<std::uint8_t, 512> buffer_{};
    Backoff backoff_;
    bool running_ = false;
    bool ever_connected_ = false;
    std::atomic<std::uint64_t> bytes_received_{0};
    std::shared_ptr<bool> alive_ = std::make_shared<bool>(true);
};

}  // namespace manikind::drivers
