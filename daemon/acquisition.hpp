#pragma once
// The daemon's device side: one driver per instrument, built from the configuration, on a
// shared io_context (serial, CAN) plus worker threads for Modbus in real time. In simulated
// mode it also owns the simulated lab and connects the drivers to its virtual devices over the
// real transports. Two ways to run:
//   step(dt)          virtual clock: the lab advances dt, Modbus is polled (the datalogger on a
//                     step worker, beside the chamber), every driver reads what was sent (the
//                     lockstep waits on real I/O events, never sleeps).
//   start_realtime()  wall clock: io thread + Modbus workers; the simulated lab (if any) is
//                     stepped by a pacing thread at `speed` x real time.
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/simulated_lab.hpp"
#include "drivers/register_map.hpp"
#include "drivers/anemometers.hpp"
#include "drivers/clock.hpp"
#include "drivers/manikin_can_driver.hpp"
#include "drivers/modbus_driver.hpp"
#include "sim/lab/sim_lab.hpp"

namespace manikind {

class Acquisition {
public:
    // Simulated mode: builds the lab (virtual devices) and connects drivers to it. `clock` must
    // outlive this object; in virtual mode it is advanced by step().
    Acquisition(const config::Config& config, drivers::ManualClock& clock, drivers::SampleSink sink,
                std::optional<sim::SimLabOptions> lab_options = std::nullopt);
    // Real mode: drivers for the devices in [devices]; nothing simulated.
    Acquisition(const config::Config& config, const drivers::Clock& clock, drivers::SampleSink sink);
    ~Acquisition();

    void start();                                   // opens every transport
    void step(double dt_s);                         // virtual clock only
    void start_realtime(double speed = 1.0);        // io thread, Modbus workers, lab pacing
    void stop();

    std::vector<drivers::DriverStatus> status() const;
    sim::SimLab* lab() { return lab_.get(); }
    drivers::ModbusDriver& chamber() { return *chamber_; }
    drivers::ModbusDriver& datalogger() { return *datalogger_; }
    drivers::ManikinCanDriver& manikin() { return *manikin_; }
    drivers::WindSonicDriver& windsonic() { return *windsonic_; }
    drivers::Csat3bDriver& csat3b() { return *csat3b_; }
    bool virtual_clock() const { return manual_clock_ != nullptr && !realtime_; }
    double lockstep_stalls() const { return lockstep_stalls_; }

private:
    void build_drivers(const config::Config& config, const drivers::Clock& clock, int manikin_fd,
                       const std::string& windsonic_path, const std::string& csat3b_path,
                       const std::string& chamber_host, int chamber_port, const std::string& datalogger_host,
                       int datalogger_port);
    void checks(std::int64_t now_ns);

    boost::asio::io_context io_;
    drivers::ManualClock* manual_clock_ = nullptr;
    drivers::SampleSink sink_;
    std::unique_ptr<sim::SimLab> lab_;
    std::unique_ptr<drivers::ModbusDriver> chamber_, datalogger_;
    std::unique_ptr<drivers::ManikinCanDriver> manikin_;
    std::unique_ptr<drivers::WindSonicDriver> windsonic_;
    std::unique_ptr<drivers::Csat3bDriver> csat3b_;
    double poll_period_s_ = 1.0;
    double next_poll_s_ = 0.0;
    bool realtime_ = false;
    std::atomic<bool> stop_{false};
    std::thread io_thread_, pacer_thread_;
    double lockstep_stalls_ = 0;
    // Virtual clock: the simulated Modbus devices answer on the stepping thread.
    void serve_modbus_here(bool on);
    bool modbus_on_caller_ = false;
    std::string manikin_open_error_;   // real mode: why can0 could not be opened
};

}  // namespace manikind
