// Thermoregulation benchmark (issue 5): one 2-h exposure at 1-s steps, and the full Fig. S22
// grid (30-50 C x 5-100 % RH at 1 C x 5 %, both convection models, both MRT settings) on two
// threads. Two floors: the irreducible arithmetic of the same network written here, independent
// of the model's code (issue 36: a floor must not be the code under test), and, as before, the
// model with its cheapest convection law (constant h), which does no psychrometrics.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <future>
#include <vector>

#include "physics/thermoreg/stolwijk.hpp"

using namespace manikind::physics::thermoreg;

namespace {

// The floor: Stolwijk's network as bare arithmetic, 6 segments x 4 layers + the central blood
// (25 nodes), 7200 explicit steps of 1 s. Per step and segment what no implementation can skip:
// conduction between the layers, perfusion with the blood, and at the skin one convection law
// (a power of the temperature difference), a saturation pressure (an exponential) and radiation.
double network_floor(double air_c, double rh_pct) {
    constexpr int segments = 6, layers = 4;
    std::array<double, segments * layers + 1> t{};
    t.fill(36.8);
    const std::array<double, segments * layers> capacity_j_k = [] {
        std::array<double, segments * layers> c{};
        for (int i = 0; i < segments * layers; ++i) c[static_cast<std::size_t>(i)] = 1.0e4 * (1.0 + 0.3 * (i % layers));
        return c;
    }();
    const double conductance_w_k = 1.5, perfusion_w_k = 0.8, area_m2 = 0.3;
    const double p_air_kpa = rh_pct / 100.0 * 0.61078 * std::exp(17.27 * air_c / (air_c + 237.3));
    for (int step = 0; step < 7200; ++step) {
        double blood_gain_w = 0.0;
        for (int s = 0; s < segments; ++s) {
            double* n = &t[static_cast<std::size_t>(s * layers)];
            double flow_w[layers] = {};
            for (int l = 0; l + 1 < layers; ++l) {
                const double q = conductance_w_k * (n[l] - n[l + 1]);
                flow_w[l] -= q;
                flow_w[l + 1] += q;
            }
            for (int l = 0; l < layers; ++l) {
                const double q = perfusion_w_k * (t.back() - n[l]);
                flow_w[l] += q;
                blood_gain_w -= q;
            }
            const double dt_skin = n[layers - 1] - air_c;
            const double h_c = 3.0 * std::pow(std::fabs(dt_skin) + 1e-9, 0.25);
            const double p_skin_kpa = 0.61078 * std::exp(17.27 * n[layers - 1] / (n[layers - 1] + 237.3));
            flow_w[layers - 1] -= area_m2 * (h_c * dt_skin + 4.7 * dt_skin + 16.5 * h_c * 0.06 * (p_skin_kpa - p_air_kpa));
            flow_w[0] += 10.0;  // metabolism
            for (int l = 0; l < layers; ++l) n[l] += flow_w[l] / capacity_j_k[static_cast<std::size_t>(s * layers + l)];
        }
        t.back() += blood_gain_w / 3.0e3;
    }
    return t[3];
}

}  // namespace

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
    auto network_ms = [&] {
        const auto t0 = clock::now();
        sink += network_floor(Exposure{}.air_temp_c, Exposure{}.rh_pct);
        return std::chrono::duration<double, std::milli>(clock::now() - t0).count();
    };
    for (int i = 0; i < 3; ++i) network_ms(), run_ms(floor_options), run_ms(coupled_options), run_ms(seed_options);
    const int reps = 31;
    std::vector<double> network_runs, floor_runs, coupled_runs, seed_runs;
    for (int i = 0; i < reps; ++i) {
        network_runs.push_back(network_ms());
        floor_runs.push_back(run_ms(floor_options));
        coupled_runs.push_back(run_ms(coupled_options));
        seed_runs.push_back(run_ms(seed_options));
    }
    auto median = [](std::vector<double> v) {
        std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
        return v[v.size() / 2];
    };
    const double network_floor_ms = median(network_runs), floor_ms = median(floor_runs), coupled_ms = median(coupled_runs),
                 seed_ms = median(seed_runs);

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
    std::printf("  floor: 25-node network, bare arithmetic   %7.3f ms  (written here, not the model's code)\n", network_floor_ms);
    std::printf("  the model, constant h_c                   %7.3f ms  ratio to floor %.2f (no convection law)\n", floor_ms,
                floor_ms / network_floor_ms);
    std::printf("  2-h run, coupled (default)                %7.3f ms  ratio to floor %.2f\n", coupled_ms, coupled_ms / network_floor_ms);
    std::printf("  2-h run, coupled (seed-compatible)        %7.3f ms  ratio to floor %.2f\n", seed_ms, seed_ms / network_floor_ms);
    std::printf("  Fig. S22 grid: %zu conditions x 2 models x 2 h, two threads: %.2f s\n", grid.size(), grid_s);
    std::printf("  (checksum %.3f)\n", sink);
    return 0;
}
