#pragma once
// The manikin's zone bus over SocketCAN. The driver reads and writes `struct can_frame` on a
// file descriptor through a Boost.Asio stream_descriptor: on a lab PC a PF_CAN raw socket bound
// to can0 (open_socketcan), in CI and the simulated lab one end of a
// socketpair(AF_UNIX, SOCK_SEQPACKET), where the kernel has no AF_CAN. Same code either way.
//
// Per zone it emits zNN.skin_temp_c, zNN.heat_flux_w_m2, zNN.heater_power_w_m2 and
// zNN.sweat_rate_g_m2_h. check() sends the host heartbeat (the manikin stops heating when it
// stalls) and marks the device stale when its own heartbeat stops. Every frame seen or sent can
// be captured to a can-utils `candump -l` log; ingest() accepts frames from a replayed log.
#include <linux/can.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>

#include <array>
#include <atomic>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "drivers/driver.hpp"
#include "protocol/manikin_can.hpp"

namespace manikind::drivers {

struct ManikinBusOptions {
    std::string device_name = "manikin";
    std::string interface = "can0";   // for the capture log and for open_socketcan
    double stale_after_s = 3.0;
    double max_skin_temp_c = 45.0;    // a zone above this is flagged out-of-range (safety is the daemon's)
    std::string open_error;           // why there is no bus (from open_socketcan), shown in status
};

// Opens a PF_CAN raw socket bound to `interface`; returns -1 and sets `error` where the kernel
// has no AF_CAN or the interface does not exist.
int open_socketcan(const std::string& interface, std::string& error);

class ManikinCanDriver final : public Driver {
public:
    // Takes ownership of `fd` (a CAN socket or a SOCK_SEQPACKET socketpair end); -1 = no bus
    // (replay only).
    ManikinCanDriver(boost::asio::io_context& io, int fd, ManikinBusOptions options, const Clock& clock,
                     SampleSink sink);
    ~ManikinCanDriver() override;

    const std::string& name() const override { return options_.device_name; }
    void start() override;
    void stop() override;
    void check(std::int64_t now_mono_ns) override;
    DriverStatus status() const override;

    bool send(const protocol::manikin_can::Setpoint& setpoint);
    bool set_run(bool run);
    bool running_command() const { return run_; }

    // Records every frame seen or sent, in `candump -l` format, to `path` (appended).
    void capture_to(const std::string& path);
    // Handles a frame as if it had arrived on the bus (replay of a capture).
    void ingest(const can_frame& frame);

    std::uint64_t frames_received() const { return frames_received_.load(); }
    std::optional<protocol::manikin_can::Heartbeat> last_heartbeat() const;

private:
    void start_read();
    void take(const can_frame& frame, std::size_t bytes);
    bool drain_waiting();
    bool write_frame(const can_frame& frame);
    void capture(const can_frame& frame);
    void emit(const std::string& channel, double value, Quality q, std::int64_t mono, std::int64_t utc);
    std::map<int, std::array<std::string, 4>> zone_channels_;  // zone -> its channels' names (ingest)

    boost::asio::io_context& io_;
    std::unique_ptr<boost::asio::posix::stream_descriptor> stream_;
    ManikinBusOptions options_;
    const Clock& clock_;
    SampleSink sink_;
    mutable std::mutex lock_;
    DriverStatus status_;
    bool run_ = false;
    std::uint8_t host_heartbeat_ = 0;
    std::optional<protocol::manikin_can::Heartbeat> heartbeat_;
    std::ofstream capture_;
    std::atomic<std::uint64_t> frames_received_{0};
    std::shared_ptr<bool> alive_ = std::make_shared<bool>(true);
};

}  // namespace manikind::drivers
