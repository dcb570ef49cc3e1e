#pragma once
// The simulated lab with the daemon's drivers connected over the real transports (libmodbus TCP
// on 127.0.0.1, pseudo-terminals, a SOCK_SEQPACKET socketpair), on the virtual clock.
#include <atomic>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "daemon/acquisition.hpp"

namespace manikind::test {

struct Collected {
    drivers::Sample last;
    std::vector<double> values;  // every value, in arrival order
    std::size_t count = 0, good = 0;
    std::map<drivers::Quality, std::size_t> by_quality;
    std::size_t n(drivers::Quality q) const {
        const auto it = by_quality.find(q);
        return it == by_quality.end() ? 0 : it->second;
    }
};

class LabFixture {
public:
    explicit LabFixture(config::Config cfg = quick_config()) {
        static std::atomic<int> serial{0};
        dir_ = std::filesystem::temp_directory_path() /
               ("manikind-test-lab-" + std::to_string(::getpid()) + "-" + std::to_string(serial++));
        cfg.simulation.runtime_dir = dir_.string();
        acq_ = std::make_unique<Acquisition>(cfg, clock_, [this](const drivers::Sample& s) { collect(s); });
        acq_->start();
    }
    ~LabFixture() {
        acq_.reset();
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }

    static config::Config quick_config() {
        config::Config c = config::default_config();
        // A silent device costs this much real time per poll; long enough that a loaded CI machine
        // answering late on loopback is not mistaken for a fault.
        c.devices.modbus_timeout_s = 0.25;
        c.simulation.manikin_period_s = 1.0;
        return c;
    }

    void run_s(double seconds, double dt_s = 1.0) {
        for (double t = 0; t < seconds - 1e-9; t += dt_s) acq_->step(dt_s);
    }
    Collected channel(const std::string& device, const std::string& channel) {
        std::lock_guard lk(lock_);
        return samples_[device + "/" + channel];
    }
    void reset_counts() {
        std::lock_guard lk(lock_);
        samples_.clear();
    }
    drivers::DriverStatus status(const std::string& device) {
        for (const auto& s : acq_->status())
            if (s.name == device) return s;
        return {};
    }
    Acquisition& acq() { return *acq_; }
    sim::SimLab& lab() { return *acq_->lab(); }
    drivers::ManualClock& clock() { return clock_; }

private:
    void collect(const drivers::Sample& s) {
        std::lock_guard lk(lock_);
        auto& c = samples_[s.device + "/" + s.channel];
        c.last = s;
        c.values.push_back(s.value);
        ++c.count;
        ++c.by_quality[s.quality];
        if (s.quality == drivers::Quality::good) ++c.good;
    }

    std::filesystem::path dir_;
    drivers::ManualClock clock_;
    std::mutex lock_;
    std::map<std::string, Collected> samples_;
    std::unique_ptr<Acquisition> acq_;
};

}  // namespace manikind::test
