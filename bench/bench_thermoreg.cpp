// Thermoregulation benchmark (issue 5): one 2-h exposure at 1-s steps, and the full Fig. S22
// grid (30-50 C x 5-100 % RH at 1 C x 5 %, both convection models, both MRT settings) on two
// threads. Floor: the same 2-h run with the cheapest convection law (constant h), which does
// no psychrometrics in the convection step.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <future>
#include <vector>

#include "physics/thermoreg/stolwijk.hpp"

using namespace manikind::physics::thermoreg;

int main() {
    using clock = std::chrono::steady_clock;
    double sink = 0.0;
    auto run_ms = [&](const ModelOptions& options) {
        const auto t0 = clock::now();
        sink += simulate(Exposure{}, options).final.core_temp_c;
        return std::chrono::duration<double, std::milli>(clock::now() - t0).count();
    };
    // Warmed up (caches, page faults, CPU clock), then the median of interleaved runs, so the
    // floor and the runs it bounds see the same machine state.
    const ModelOptions floor_options{ConvectionModel::constant_stolwijk, false, default_clo},
        coupled_options{ConvectionModel::coupled, false, default_clo},
        seed_options{ConvectionModel::coupled, true, default_clo};
    for (int i = 0; i < 3; ++i) run_ms(floor_options), run_ms(coupled_options), run_ms(seed_options);
    const int reps = 31;
    std::vector<double> floor_runs, coupled_runs, seed_runs;
    for (int i = 0; i < reps; ++i) {
        floor_runs.push_back(run_ms(floor_options));
        coupled_runs.push_back(run_ms(coupled_options));
        seed_runs.push_back(run_ms(seed_options));
    }
    auto median = [](std::vector<double> v) {
        std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
        return v[v.size() / 2];
    };
    const double floor_ms = median(floor_runs), coupled_ms = median(coupled_runs), seed_ms = median(seed_runs);

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
    std::printf("  medians of %d interleaved runs after 3 warm-up runs each\n", reps);
    std::printf("  floor: 2-h run, constant h_c              %7.3f ms  (same steps, no convection law)\n", floor_ms);
    std::printf("  2-h run, coupled (default)                %7.3f ms  ratio to floor %.2f\n", coupled_ms, coupled_ms / floor_ms);
    std::printf("  2-h run, coupled (seed-compatible)        %7.3f ms  ratio to floor %.2f\n", seed_ms, seed_ms / floor_ms);
    std::printf("  Fig. S22 grid: %zu conditions x 2 models x 2 h, two threads: %.2f s\n", grid.size(), grid_s);
    std::printf("  (checksum %.3f)\n", sink);
    return 0;
}
