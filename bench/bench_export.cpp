// `manikin export` of long campaigns (issue 36, item 2): memory flat in the number of trials, and
// time against a raw scan of the same rows. Builds recorder databases of 45 and 450 trials of the
// demo's size (91 channels: 35 zones' skin temperature and heat flux, 8 EE181 probes' air
// temperature and humidity, 4 wall thermocouples, the WindSonic; 2000 one-second steps, 182 000
// samples a trial), then, each in a fresh process, median of 3:
//   - manikin export <campaign> out (CSV) and out.h5 (HDF5, with the analysis), wall and peak RSS;
//   - the floor: a program of its own (a forked child) reading the same rows of every trial with
//     the sqlite3 C API, the one statement a trial the exporter's reader runs, summing the values.
//   bench_export [trial counts..., default 45 450]
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <sqlite3.h>

#include "base/lazy_library.hpp"
#include "bench/child_run.hpp"
#include "store/database.hpp"

namespace fs = std::filesystem;
namespace rec = manikind::recorder;
using Clock = std::chrono::steady_clock;

namespace {

constexpr int kSteps = 2000;
constexpr std::int64_t kStepNs = 1'000'000'000;

// A campaign of `trials` done trials (3 replicates a case), its samples as the recorder stores them.
void build_database(const fs::path& path, int trials) {
    fs::remove(path);
    auto db = rec::Database::open(path);
    const auto campaign = db.create_campaign("bench", "{}");
    const auto manikin = db.device_id("manikin", "can", "vcan0");
    const auto logger = db.device_id("datalogger", "modbus", "127.0.0.1:1502");
    const auto sonic = db.device_id("windsonic", "serial", "/dev/ttyS0");
    std::vector<std::int64_t> channels;
    for (int z = 1; z <= 35; ++z) {
        channels.push_back(db.channel_id(manikin, fmt::format("z{:02d}.skin_temp_c", z), "°C"));
        channels.push_back(db.channel_id(manikin, fmt::format("z{:02d}.heat_flux_w_m2", z), "W/m²"));
    }
    for (int k = 1; k <= 8; ++k) {
        channels.push_back(db.channel_id(logger, fmt::format("ee181_{}.air_temp_c", k), "°C"));
        channels.push_back(db.channel_id(logger, fmt::format("ee181_{}.air_rh_pct", k), "%"));
    }
    for (int k = 1; k <= 4; ++k) channels.push_back(db.channel_id(logger, fmt::format("wall_tc_{}.wall_temp_c", k), "°C"));
    channels.push_back(db.channel_id(sonic, "air_speed_m_s", "m/s"));
    std::int64_t case_id = 0;
    std::vector<rec::SampleRow> rows;
    for (int t = 0; t < trials; ++t) {
        if (t % 3 == 0) case_id = db.add_case(campaign, fmt::format("case {}", t / 3 + 1), fmt::format("{{\"id\": {}}}", t / 3 + 1), t / 3);
        const auto trial = db.create_trial(campaign, case_id, t % 3 + 1);
        const std::int64_t mono0 = static_cast<std::int64_t>(t) * (kSteps + 600) * kStepNs;
        const std::int64_t utc0 = 1'790'000'000'000'000'000 + mono0;
        db.add_event(trial, mono0, utc0, "info", "stage", "acquiring");
        rows.clear();
        for (int s = 0; s < kSteps; ++s)
            for (std::size_t k = 0; k < channels.size(); ++k)
                rows.push_back({trial, channels[k], mono0 + s * kStepNs + static_cast<std::int64_t>(k) * 1000, utc0 + s * kStepNs,
                                (k < 70 ? (k % 2 ? 45.0 : 34.0) : 20.0) + 0.001 * static_cast<double>((s * 7 + static_cast<int>(k)) % 13), 0});
        db.insert_samples(rows);
        db.add_event(trial, mono0 + kSteps * kStepNs, utc0 + kSteps * kStepNs, "info", "stage", "stopping");
        db.set_trial_state(trial, "done", "", utc0 + kSteps * kStepNs);
    }
}

using manikind::bench::ChildRun;
using Run = ChildRun;

Run run_manikin(const std::string& manikin, std::vector<std::string> args) { return manikind::bench::run_program(manikin, std::move(args)); }

// The floor, in a child process of its own: every trial's rows, the reader's one statement.
Run run_floor(const fs::path& db_path, int trials) {
    std::fflush(stdout);
    const auto t0 = Clock::now();
    const pid_t pid = fork();
    if (pid == 0) {
        sqlite3* db = nullptr;
        if (sqlite3_open_v2(db_path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) _exit(1);
        sqlite3_stmt* q = nullptr;
        sqlite3_prepare_v2(db, "SELECT mono_ns, channel_id, utc_ns, value, quality FROM samples WHERE id >= ?1 AND id < ?2", -1, &q,
                           nullptr);
        double sum = 0;
        long n = 0;
        for (std::int64_t t = 1; t <= trials; ++t) {  // ids are (trial << 36) + n (store/database_schema.cpp, version 8)
            sqlite3_bind_int64(q, 1, t << 36);
            sqlite3_bind_int64(q, 2, (t + 1) << 36);
            while (sqlite3_step(q) == SQLITE_ROW) {
                sum += sqlite3_column_double(q, 3) + static_cast<double>(sqlite3_column_int64(q, 0) + sqlite3_column_int64(q, 1) +
                                                                          sqlite3_column_int64(q, 2) + sqlite3_column_int64(q, 4));
                ++n;
            }
            sqlite3_reset(q);
        }
        sqlite3_finalize(q);
        sqlite3_close(db);
        _exit(n > 0 && sum != 0 ? 0 : 2);
    }
    return manikind::bench::wait_child(pid, t0);
}

template <typename F>
Run median_of_3(F run) {
    std::vector<Run> runs{run(), run(), run()};
    std::sort(runs.begin(), runs.end(), [](const Run& a, const Run& b) { return a.wall_s < b.wall_s; });
    Run m = runs[1];
    for (const auto& r : runs) m.peak_mb = std::max(m.peak_mb, r.peak_mb), m.status = std::max(m.status, r.status);
    return m;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<int> counts;
    for (int i = 1; i < argc; ++i) counts.push_back(std::max(1, std::atoi(argv[i])));
    if (counts.empty()) counts = {45, 450};
    const std::string manikin = manikind::LazyLibrary::program_directory() + "/manikin";
    const fs::path dir = fs::temp_directory_path() / ("manikind-bench-export-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::printf("manikin export, fresh processes, median of 3 (peak RSS: the largest of the 3)\n");
    for (const int trials : counts) {
        const fs::path db = dir / fmt::format("{}.db", trials);
        const auto t0 = Clock::now();
        build_database(db, trials);
        std::printf("%d trials, %d samples each: database built in %.0f s (%.0f MB)\n", trials, kSteps * 91,
                    std::chrono::duration<double>(Clock::now() - t0).count(), static_cast<double>(fs::file_size(db)) / 1e6);
        const Run floor = median_of_3([&] { return run_floor(db, trials); });
        const Run csv = median_of_3([&] {
            fs::remove_all(dir / "csv");
            return run_manikin(manikin, {"export", "--db", db.string(), "bench", (dir / "csv").string()});
        });
        const Run h5 = median_of_3([&] {
            fs::remove(dir / "out.h5");
            return run_manikin(manikin, {"export", "--db", db.string(), "bench", (dir / "out.h5").string()});
        });
        std::printf("  floor (sqlite3 scan of the rows)  %7.2f s   peak %6.1f MB   exit %d\n", floor.wall_s, floor.peak_mb, floor.status);
        std::printf("  export CSV                        %7.2f s   peak %6.1f MB   exit %d   %.2fx the floor\n", csv.wall_s, csv.peak_mb,
                    csv.status, csv.wall_s / floor.wall_s);
        std::printf("  export HDF5 (+ analysis)          %7.2f s   peak %6.1f MB   exit %d   %.2fx the floor\n", h5.wall_s, h5.peak_mb,
                    h5.status, h5.wall_s / floor.wall_s);
        fs::remove_all(dir / "csv");
        fs::remove(dir / "out.h5");
        fs::remove(db);
    }
    fs::remove_all(dir);
    return 0;
}
