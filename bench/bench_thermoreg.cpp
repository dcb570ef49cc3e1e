// Thermoregulation benchmark (issue 5): one 2-h exposure at 1-s steps, and the full Fig. S22
// grid (30-50 C x 5-100 % RH at 1 C x 5 %, both convection models, both MRT settings) on two
// threads. Floor: the same 2-h run with the cheapest convection law (constant h), which does
// no psychrometrics in the convection step.
#include <chrono>
#include <cstdio>
#include <future>
#include <vector>

#include "physics/thermoreg/stolwijk.hpp"

using namespace manikind::physics::thermoreg;

int main() {
    using clock = std::chrono::steady_clock;
    auto time_ms = [](auto&& f, int reps) {
        const auto t0 = clock::now();
        for (int i = 0; i < reps; ++i) f();
        return std::chrono::duration<double, std::milli>(clock::now() - t0).count() / reps;
    };
    double sink = 0.0;
    const int reps = 20;
    const double floor_ms = time_ms([&] { sink += simulate(Exposure{}, {ConvectionModel::constant_stolwijk, false}).final.core_temp_c; }, reps);
    const double coupled_ms = time_ms([&] { sink += simulate(Exposure{}, {ConvectionModel::coupled, false}).final.core_temp_c; }, reps);
    const double seed_ms = time_ms([&] { sink += simulate(Exposure{}, {ConvectionModel::coupled, true}).final.core_temp_c; }, reps);

    std::vector<Exposure> grid;
    for (int mrt_mode = 0; mrt_mode < 2; ++mrt_mode)
        for (double t = 30.0; t <= 50.0 + 1e-9; t += 1.0)
            for (double rh = 5.0; rh <= 100.0 + 1e-9; rh += 5.0) {
                Exposure e;
                e.air_temp_c = t;
                e.rh_pct = rh;
                e.mrt_c = mrt_mode == 0 ? t : 55.0;
                grid.push_back(e);
            }
    const auto t0 = clock::now();
    auto worker = [&](std::size_t begin) {
        double s = 0.0;
        for (std::size_t i = begin; i < grid.size(); i += 2)
            s += simulate(grid[i], {ConvectionModel::coupled, false}).final.core_temp_c +
                 simulate(grid[i], {ConvectionModel::dt_only, false}).final.core_temp_c;
        return s;
    };
    auto other = std::async(std::launch::async, worker, 1);
    sink += worker(0) + other.get();
    const double grid_s = std::chrono::duration<double>(clock::now() - t0).count();

    std::printf("thermoregulation benchmark (7200 steps of 1 s per run)\n");
    std::printf("  floor: 2-h run, constant h_c              %7.2f ms\n", floor_ms);
    std::printf("  2-h run, coupled (default)                %7.2f ms\n", coupled_ms);
    std::printf("  2-h run, coupled (seed-compatible)        %7.2f ms  (its direction loop computes 36 p_sat per step)\n", seed_ms);
    std::printf("  Fig. S22 grid: %zu conditions x 2 models x 2 h, two threads: %.2f s\n", grid.size(), grid_s);
    std::printf("  (checksum %.3f)\n", sink);
    return 0;
}
