#pragma once
// Modbus devices: the chamber controller (setpoints, process values) and the datalogger that
// carries the EE181 air T/RH probes and the wall thermocouples. TCP through our own client
// (drivers/modbus_tcp_client.hpp: a poll's requests in one send, their replies in one recv), RTU
// through libmodbus. Both block, so in real time each Modbus device polls on its own worker thread and cannot stall the
// io_context the serial and CAN drivers share; on the virtual clock the acquisition loop calls
// poll() itself, once per tick. Errors are classified (timeout, exception, connection lost),
// counted, and turn the point's sample into comm_error; the connection is re-opened with backoff.
#include <modbus/modbus.h>

#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "drivers/driver.hpp"
#include "drivers/modbus_tcp_client.hpp"
#include "protocol/modbus_blocks.hpp"
#include "protocol/modbus_registers.hpp"
#include "protocol/probe_scaling.hpp"

namespace manikind::drivers {

struct ModbusPoint {
    std::string channel;                           // "air_temp_c", "ee181_1.air_rh_pct"
    protocol::modbus_registers::RegisterSpec spec;
    int unit_id = 1;
    bool input_register = false;                   // function 04 instead of 03
    std::optional<protocol::ProbeScaling> scaling; // probe scaling after the register decode
    double valid_min = -1e300, valid_max = 1e300;  // physical range: outside -> out_of_range
    bool poll = true;                              // setpoints are written, not polled
};

struct ModbusOptions {
    std::string device_name = "chamber";
    std::string host = "127.0.0.1";                // TCP; or
    int port = 502;
    std::string serial_path;                       // RTU when set (e.g. /dev/ttyUSB1)
    int baud = 19200;
    double response_timeout_s = 0.5;
    double poll_period_s = 1.0;                    // worker thread, real time
    int max_gap_registers = 0;                     // unused registers one request may span (0: contiguous only)
    int requests_in_flight = 1;                    // TCP: requests of one poll sent before their replies are read
    std::vector<ModbusPoint> points;
};

class ModbusDriver final : public Driver {
public:
    ModbusDriver(ModbusOptions options, const Clock& clock, SampleSink sink);
    ~ModbusDriver() override;

    const std::string& name() const override { return options_.device_name; }
    void start() override;                      // connects (failure is counted, retried by poll)
    void stop() override;                       // stops the worker and closes
    void check(std::int64_t now_mono_ns) override;
    DriverStatus status() const override;

    // One read of every polled point. Safe to call from any thread (serialised internally).
    void poll();
    // The same read, its samples returned instead of handed to the sink (the caller delivers
    // them, e.g. on the thread that owns the sink's lock).
    std::vector<Sample> read_all();
    // Real-time mode: a worker thread that polls every poll_period_s until stop().
    void start_worker();

    // Writes one writable point. Returns an empty string on success, else why not (the register's
    // limit named, read-only, or the Modbus error).
    std::string write(const std::string& channel, double value);
    // Reads one point now (any point, polled or not).
    std::optional<double> read(const std::string& channel);

    const ModbusOptions& options() const { return options_; }
    // TCP: see ModbusTcpClient::set_sent_hook (the simulated lab answering on this thread).
    void set_sent_hook(ModbusTcpClient::SentHook hook) {
        std::lock_guard lk(io_lock_);
        tcp_.set_sent_hook(std::move(hook));
    }
    // Before start_worker(): the simulated lab at N x real time polls N times as often.
    void set_poll_period(double seconds) { options_.poll_period_s = seconds; }

private:
    bool ensure_connected(std::int64_t now_ns);
    void disconnect();
    void record_error(const std::string& what);
    bool is_open() const { return tcp() ? tcp_.is_open() : ctx_ != nullptr; }
    bool tcp() const { return options_.serial_path.empty(); }
    std::optional<double> read_point(const ModbusPoint& p, Quality& quality);
    // The reply to one block's request: err 0 and its words, or an error (ENOTCONN: not sent or
    // not answered, the link having failed on an earlier request of the same poll).
    struct BlockRead {
        int err = 0;
        std::vector<std::uint16_t> words;
        std::string why;  // a malformed reply: what was wrong with it
    };
    // Reads blocks[0..n): over TCP their requests go out together; over RTU one after another.
    void read_blocks(std::span<const protocol::modbus_blocks::ReadBlock> blocks, std::vector<BlockRead>& out);
    void count_error(int err, const std::string& what);  // classify, count, drop a broken link
    double decode_point(const ModbusPoint& p, std::span<const std::uint16_t> words, Quality& quality) const;
    const ModbusPoint* find(const std::string& channel) const;

    ModbusOptions options_;
    // Polled points grouped into requests (protocol/modbus_blocks.hpp). A block the device
    // refuses with "illegal data address" is split into single points for good.
    std::vector<protocol::modbus_blocks::ReadBlock> blocks_;
    const Clock& clock_;
    SampleSink sink_;
    std::mutex io_lock_;                 // one poll or write at a time on the connection
    ModbusTcpClient tcp_;                // TCP
    modbus_t* ctx_ = nullptr;            // RTU (libmodbus)
    Backoff backoff_;
    bool ever_connected_ = false;
    mutable std::mutex status_lock_;
    DriverStatus status_;
    std::thread worker_;
    std::mutex worker_lock_;
    std::condition_variable worker_cv_;
    bool worker_stop_ = false;
};

}  // namespace manikind::drivers
