// Benchmark (not a test): the simulated lab with every device and every driver connected over
// the real transports. (1) A 75-min trial on the virtual clock: wall time, beside its floor
// measured in the same run, the world model alone (physics of 35 zones, no devices, no I/O).
// (2) Real-time mode (1x): CPU used by the whole stack as a percentage of one core.
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>

#include <fmt/core.h>

#include "daemon/acquisition.hpp"

namespace {

using SteadyClock = std::chrono::steady_clock;
double seconds_since(SteadyClock::time_point t0) { return std::chrono::duration<double>(SteadyClock::now() - t0).count(); }

double cpu_seconds() {
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
           static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) * 1e-6;
}

manikind::config::Config bench_config(const std::string& tag) {
    auto c = manikind::config::default_config();
    c.simulation.runtime_dir = (std::filesystem::temp_directory_path() / fmt::format("manikind-bench-{}-{}", tag, ::getpid())).string();
    return c;
}

void start_manikin(manikind::Acquisition& acq) {
    manikind::protocol::manikin_can::Setpoint sp;
    sp.value = 35.0;
    acq.manikin().send(sp);
    acq.manikin().set_run(true);
    acq.chamber().write("air_temp_remote_setpoint_c", 35.0);
}

}  // namespace

int main() {
    const double trial_s = 4500.0;  // 75 min (Methods)
    std::atomic<std::uint64_t> samples{0};
    auto sink = [&](const manikind::drivers::Sample&) { ++samples; };

    // Floor: the world model alone for the same virtual time.
    double floor_s = 0.0;
    {
        const auto cfg = bench_config("floor");
        manikind::sim::World world(manikind::simulated_lab_options(cfg).world);
        manikind::protocol::manikin_can::Setpoint sp;
        sp.value = 35.0;
        world.manikin_command(sp);
        world.manikin_control(true);
        const auto t0 = SteadyClock::now();
        for (double t = 0; t < trial_s; t += 1.0) {
            world.step(1.0);
            world.manikin_control(true);
        }
        floor_s = seconds_since(t0);
    }

    // The whole simulated lab, every driver, real transports, virtual clock.
    double virtual_s = 0.0, stalls = 0.0;
    {
        const auto cfg = bench_config("virtual");
        manikind::drivers::ManualClock clock;
        manikind::Acquisition acq(cfg, clock, sink);
        acq.start();
        start_manikin(acq);
        const auto t0 = SteadyClock::now();
        for (double t = 0; t < trial_s; t += cfg.simulation.step_s) acq.step(cfg.simulation.step_s);
        virtual_s = seconds_since(t0);
        stalls = acq.lockstep_stalls();
        std::filesystem::remove_all(cfg.simulation.runtime_dir);
    }
    fmt::print("simulated lab, 75-min trial on the virtual clock (1 s steps, 5 devices, {} samples):\n", samples.load());
    fmt::print("  whole stack      {:8.3f} s wall   (target < 2 s)   lockstep stalls {}\n", virtual_s, stalls);
    fmt::print("  floor: world only{:8.3f} s wall   (physics of 35 zones, no devices)\n", floor_s);
    fmt::print("  ratio            {:8.1f} x\n", virtual_s / floor_s);

    // Real time: the lab paced at 1x, drivers on the io thread and Modbus workers.
    const double window_s = 5.0;
    {
        const auto cfg = bench_config("realtime");
        manikind::drivers::ManualClock clock;
        manikind::Acquisition acq(cfg, clock, sink);
        acq.start();
        start_manikin(acq);
        const auto s0 = samples.load();
        acq.start_realtime(1.0);
        const double cpu0 = cpu_seconds();
        const auto t0 = SteadyClock::now();
        std::this_thread::sleep_for(std::chrono::duration<double>(window_s));
        const double cpu = cpu_seconds() - cpu0;
        const double wall = seconds_since(t0);
        acq.stop();
        fmt::print("real-time mode (1x) for {:.1f} s: {} samples, CPU {:.3f} s = {:.2f} % of one core (issue 18: < 1 %)\n",
                   wall, samples.load() - s0, cpu, 100.0 * cpu / wall);
        std::filesystem::remove_all(cfg.simulation.runtime_dir);
    }
    return 0;
}
