#include "daemon/acquisition.hpp"
#include "base/guarded.hpp"

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/post.hpp>
#include <fmt/format.h>

#include <chrono>
#include <filesystem>
#include <unistd.h>

#include "drivers/register_map.hpp"
#include "base/user_error.hpp"

namespace manikind {

Acquisition::Acquisition(const config::Config& config, drivers::ManualClock& clock, drivers::SampleSink sink,
                         std::optional<sim::SimLabOptions> lab_options)
    : manual_clock_(&clock), sink_(std::move(sink)) {
    lab_ = std::make_unique<sim::SimLab>(lab_options ? std::move(*lab_options) : simulated_lab_options(config));
    const auto ep = lab_->endpoints();
    build_drivers(config, clock, lab_->take_manikin_fd(), ep.windsonic_path, ep.csat3b_path, ep.chamber_host,
                  ep.chamber_port, ep.chamber_host, ep.datalogger_port);
}

Acquisition::Acquisition(const config::Config& config, const drivers::Clock& clock, drivers::SampleSink sink)
    : sink_(std::move(sink)) {
    const int fd = drivers::open_socketcan(config.devices.manikin_interface, manikin_open_error_);
    const auto& d = config.devices;
    build_drivers(config, clock, fd, d.windsonic_path, d.csat3b_path, d.chamber.host, static_cast<int>(d.chamber.port),
                  d.datalogger.host, static_cast<int>(d.datalogger.port));
}

void Acquisition::build_drivers(const config::Config& config, const drivers::Clock& clock, int manikin_fd,
                                const std::string& windsonic_path, const std::string& csat3b_path,
                                const std::string& chamber_host, int chamber_port, const std::string& datalogger_host,
                                int datalogger_port) {
    const auto& d = config.devices;
    poll_period_s_ = d.poll_period_s;
    auto modbus = [&](const char* name, const config::ModbusDeviceConfig& m, const std::string& host, int port) {
        drivers::ModbusOptions o;
        o.device_name = name;
        o.host = host;
        o.port = port;
        o.serial_path = lab_ ? std::string() : m.serial;
        o.baud = static_cast<int>(m.baud);
        o.response_timeout_s = d.modbus_timeout_s;
        o.poll_period_s = d.poll_period_s;
        o.max_gap_registers = static_cast<int>(m.max_gap_registers);
        // The simulated devices answer every request of a poll in order (sim/devices/modbus_server):
        // the poll's requests go out in one send and come back in one wake-up.
        o.requests_in_flight = lab_ ? 16 : static_cast<int>(m.requests_in_flight);
        o.points = modbus_points(register_map_from_setting(m.register_map, name, config.source_dir));
        return std::make_unique<drivers::ModbusDriver>(std::move(o), clock, sink_);
    };
    chamber_ = modbus("chamber", d.chamber, chamber_host, chamber_port);
    datalogger_ = modbus("datalogger", d.datalogger, datalogger_host, datalogger_port);
    drivers::ManikinBusOptions mo;
    mo.interface = d.manikin_interface;
    mo.stale_after_s = d.stale_after_s;
    mo.max_skin_temp_c = config.safety.max_skin_temp_c;
    mo.open_error = manikin_open_error_;
    manikin_ = std::make_unique<drivers::ManikinCanDriver>(io_, manikin_fd, mo, clock, sink_);
    if (!d.manikin_capture.empty()) manikin_->capture_to(d.manikin_capture);  // candump -l, for `manikin replay`
    windsonic_ = std::make_unique<drivers::WindSonicDriver>(
        io_, drivers::SerialOptions{"windsonic", windsonic_path, static_cast<unsigned>(d.windsonic_baud), d.stale_after_s},
        clock, sink_);
    csat3b_ = std::make_unique<drivers::Csat3bDriver>(
        io_, drivers::SerialOptions{"csat3b", csat3b_path, static_cast<unsigned>(d.csat3b_baud), d.stale_after_s},
        clock, sink_);
}

Acquisition::~Acquisition() { stop(); }

void Acquisition::start() {
    chamber_->start();
    datalogger_->start();
    manikin_->start();
    windsonic_->start();
    csat3b_->start();
}

void Acquisition::checks(std::int64_t now_ns) {
    chamber_->check(now_ns);
    datalogger_->check(now_ns);
    manikin_->check(now_ns);
    windsonic_->check(now_ns);
    csat3b_->check(now_ns);
}

void Acquisition::step(double dt_s) {
    if (!manual_clock_ || realtime_) throw std::logic_error("Acquisition::step needs the virtual clock");
    const auto ws0 = windsonic_->bytes_received(), cs0 = csat3b_->bytes_received();
    const auto mf0 = manikin_->frames_received();
    if (!modbus_on_caller_) serve_modbus_here(true);
    lab_->step(dt_s);
    manual_clock_->advance_s(dt_s);
    // The simulated Modbus devices answer on this thread, inside each driver's transaction
    // (serve_modbus_here): both polls read the lab as this step left it, with no thread
    // hand-off. The chamber's samples reach the sink now, the datalogger's after the bus reads
    // below (the order the lockstep always had).
    const double now_s = manual_clock_->elapsed_s();
    const bool poll_due = now_s + 1e-9 >= next_poll_s_;
    std::vector<drivers::Sample> datalogger_samples;
    if (poll_due) {
        next_poll_s_ = now_s + poll_period_s_;
        chamber_->poll();
        datalogger_samples = datalogger_->read_all();
    }
    const auto ws_expected = windsonic_->status().connected ? lab_->serial_bytes_last_step("windsonic") : 0;
    const auto cs_expected = csat3b_->status().connected ? lab_->serial_bytes_last_step("csat3b") : 0;
    const auto mf_expected = lab_->can_frames_last_step();
    // Lockstep: wait (on I/O events, never a sleep) until every driver has read what the lab
    // sent this step. A pty delivers asynchronously, so this is a real wait, capped at 0.5 s.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(500);
    while (windsonic_->bytes_received() - ws0 < ws_expected || csat3b_->bytes_received() - cs0 < cs_expected ||
           manikin_->frames_received() - mf0 < mf_expected) {
        if (std::chrono::steady_clock::now() > deadline) {
            ++lockstep_stalls_;
            break;
        }
        if (io_.stopped()) io_.restart();
        io_.run_one_for(std::chrono::milliseconds(50));
    }
    if (io_.stopped()) io_.restart();
    io_.poll();  // completions already queued (errors, writes)
    for (const auto& s : datalogger_samples) sink_(s);
    checks(manual_clock_->mono_ns());
}

void Acquisition::serve_modbus_here(bool on) {
    if (!lab_ || modbus_on_caller_ == on) return;
    lab_->serve_modbus_on_caller(on);
    auto hook = [this](const char* device) -> drivers::ModbusTcpClient::SentHook {
        if (!modbus_on_caller_) return {};
        return [lab = lab_.get(), device](int fd, std::size_t requests, std::int64_t deadline_ns) {
            lab->answer_modbus(device, fd, requests, deadline_ns);
        };
    };
    modbus_on_caller_ = on;
    chamber_->set_sent_hook(hook("chamber"));
    datalogger_->set_sent_hook(hook("datalogger"));
}

void Acquisition::start_realtime(double speed) {
    serve_modbus_here(false);  // paced: each device answers on its own thread, as a real one
    realtime_ = true;
    stop_ = false;
    if (lab_) {  // keep the virtual poll rate when the simulated lab runs faster than the wall clock
        chamber_->set_poll_period(poll_period_s_ / speed);
        datalogger_->set_poll_period(poll_period_s_ / speed);
    }
    // Readings between two pacing steps get distinct, increasing stamps (drivers/clock.hpp).
    if (manual_clock_) manual_clock_->set_pace(speed);
    chamber_->start_worker();
    datalogger_->start_worker();
    io_thread_ = std::thread([this] {
        auto guard = boost::asio::make_work_guard(io_);
        // A driver's handler that throws (a frame no check foresaw) is lost; reading goes on.
        run_guarded("acquisition i/o", [this] {
            while (!stop_) io_.run_for(std::chrono::milliseconds(200));
        });
    });
    // Checks (and the simulated lab, if any) on a paced thread.
    pacer_thread_ = std::thread([this, speed] {
        run_guarded("simulated lab pacing", [&] {
            const double tick_s = 0.1;
            auto next = std::chrono::steady_clock::now();
            drivers::SystemClock sys;
            while (!stop_) {
                next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(tick_s));
                if (lab_) {
                    lab_->step(tick_s * speed);
                    if (manual_clock_) manual_clock_->advance_s(tick_s * speed);
                }
                boost::asio::post(io_, [this, now = manual_clock_ ? manual_clock_->mono_ns() : sys.mono_ns()] { checks(now); });
                std::this_thread::sleep_until(next);
            }
        });
    });
}

void Acquisition::stop() {
    stop_ = true;
    if (pacer_thread_.joinable()) pacer_thread_.join();
    if (io_thread_.joinable()) io_thread_.join();
    if (chamber_) chamber_->stop();
    if (datalogger_) datalogger_->stop();
    if (windsonic_) windsonic_->stop();
    if (csat3b_) csat3b_->stop();
    if (manikin_) manikin_->stop();
}

std::vector<drivers::DriverStatus> Acquisition::status() const {
    return {chamber_->status(), datalogger_->status(), manikin_->status(), windsonic_->status(), csat3b_->status()};
}

}  // namespace manikind
