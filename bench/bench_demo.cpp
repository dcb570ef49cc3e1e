// The virtual lab against its floor (issue 36, item 1): `manikin demo` (a campaign through the
// daemon, every device on its real transport, the virtual clock), a fresh process, beside the
// floor measured in the same run, in a child process of its own: the world model stepping the
// same virtual time in 1-s steps and writing the same number of values to SQLite through the C
// API (one prepared INSERT into a table of the recorder's shape, a transaction per [recorder]
// commit_interval_s of virtual time, 30 s: the recorder commits at most that far apart, and on the
// virtual clock its batches are larger still, so the floor pays no more commits than the demo).
// The virtual time and the count are the demo's own, read from its database.
// Prints wall and CPU (user + system) of both; the goal is the demo's CPU at most 2.5x the floor's.
//   bench_demo [cases, default 15] [replicates, default 3]
#include <sqlite3.h>
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

#include "base/lazy_library.hpp"
#include "bench/child_run.hpp"
#include "daemon/config.hpp"
#include "daemon/simulated_lab.hpp"
#include "sim/world/world.hpp"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

using Run = manikind::bench::ChildRun;
using manikind::bench::wait_child;

Run run_demo(const std::string& manikin, const fs::path& out, int cases, int replicates) {
    fs::remove_all(out);
    return manikind::bench::run_program(manikin, {"demo", "--cases", std::to_string(cases), "--replicates", std::to_string(replicates),
                                                  "--out", out.string()},
                                        true);
}

struct Work {
    double virtual_s = 0;
    long long values = 0;
};

// The demo's virtual time (first to last stamp of every stored reading) and its count of values.
Work work_of(const fs::path& db_path) {
    sqlite3* db = nullptr;
    Work w;
    if (sqlite3_open_v2(db_path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) return w;
    sqlite3_stmt* q = nullptr;
    sqlite3_prepare_v2(db,
                       "SELECT (SELECT count(*) FROM samples) + (SELECT count(*) FROM idle_samples),"
                       " min(lo), max(hi) FROM (SELECT min(utc_ns) lo, max(utc_ns) hi FROM samples"
                       " UNION ALL SELECT min(utc_ns), max(utc_ns) FROM idle_samples)",
                       -1, &q, nullptr);
    if (sqlite3_step(q) == SQLITE_ROW) {
        w.values = sqlite3_column_int64(q, 0);
        w.virtual_s = static_cast<double>(sqlite3_column_int64(q, 2) - sqlite3_column_int64(q, 1)) * 1e-9;
    }
    sqlite3_finalize(q);
    sqlite3_close(db);
    return w;
}

// The floor, in a child: the world for the same virtual time, and the same count of values
// inserted, spread evenly over the virtual seconds.
Run run_floor(const Work& work, const fs::path& db_path) {
    std::fflush(stdout);
    fs::remove(db_path);
    const auto t0 = Clock::now();
    const pid_t pid = fork();
    if (pid == 0) {
        auto cfg = manikind::config::default_config();
        manikind::sim::World world(manikind::simulated_lab_options(cfg).world);
        manikind::protocol::manikin_can::Setpoint sp;
        sp.value = 35.0;
        world.manikin_command(sp);
        world.manikin_control(true);
        sqlite3* db = nullptr;
        sqlite3_open(db_path.c_str(), &db);
        sqlite3_exec(db, "PRAGMA journal_mode = WAL; PRAGMA synchronous = NORMAL;"
                         "CREATE TABLE samples (id INTEGER PRIMARY KEY, trial_id INTEGER NOT NULL, channel_id INTEGER NOT NULL,"
                         " mono_ns INTEGER NOT NULL, utc_ns INTEGER NOT NULL, value REAL, quality INTEGER NOT NULL)",
                     nullptr, nullptr, nullptr);
        sqlite3_stmt* ins = nullptr;
        sqlite3_prepare_v2(db, "INSERT INTO samples VALUES (?1, 1, ?2, ?3, ?4, ?5, 0)", -1, &ins, nullptr);
        const long long seconds = std::max<long long>(1, static_cast<long long>(work.virtual_s));
        const long long commit_every_s = std::max<long long>(1, static_cast<long long>(cfg.recorder_commit_interval_s));
        long long written = 0, id = 0;
        for (long long s = 0; s < seconds; ++s) {
            world.step(1.0);
            world.manikin_control(true);
            const long long due = work.values * (s + 1) / seconds;
            if (s % commit_every_s == 0) sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr);
            for (int channel = 0; written < due; ++written, ++channel) {
                sqlite3_bind_int64(ins, 1, ++id);
                sqlite3_bind_int64(ins, 2, channel);
                sqlite3_bind_int64(ins, 3, s * 1'000'000'000LL + channel);
                sqlite3_bind_int64(ins, 4, 1'790'000'000'000'000'000LL + s * 1'000'000'000LL);
                sqlite3_bind_double(ins, 5, 34.0 + 0.001 * static_cast<double>(channel));
                sqlite3_step(ins);
                sqlite3_reset(ins);
            }
            if ((s + 1) % commit_every_s == 0 || s + 1 == seconds) sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr);
        }
        sqlite3_finalize(ins);
        sqlite3_close(db);
        _exit(written == work.values ? 0 : 1);
    }
    return wait_child(pid, t0);
}

}  // namespace

int main(int argc, char** argv) {
    const int cases = argc > 1 ? std::clamp(std::atoi(argv[1]), 1, 15) : 15;
    const int replicates = argc > 2 ? std::clamp(std::atoi(argv[2]), 1, 5) : 3;
    const std::string manikin = manikind::LazyLibrary::program_directory() + "/manikin";
    const fs::path dir = fs::temp_directory_path() / ("manikind-bench-demo-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::vector<double> demo_wall, demo_cpu, floor_wall, floor_cpu;
    Work work;
    for (int run = 0; run < 3; ++run) {  // interleaved: demo, then its floor
        const Run d = run_demo(manikin, dir / "demo", cases, replicates);
        if (d.status != 0) {
            std::fprintf(stderr, "bench_demo: manikin demo exited %d\n", d.status);
            return 1;
        }
        work = work_of(dir / "demo" / "manikind.db");
        const Run f = run_floor(work, dir / "floor.db");
        demo_wall.push_back(d.wall_s), demo_cpu.push_back(d.cpu_s), floor_wall.push_back(f.wall_s), floor_cpu.push_back(f.cpu_s);
        std::printf("run %d: demo %.2f s wall %.2f s CPU; floor %.2f s wall %.2f s CPU\n", run + 1, d.wall_s, d.cpu_s, f.wall_s, f.cpu_s);
        std::fflush(stdout);
    }
    const auto median = [](std::vector<double> v) {
        std::sort(v.begin(), v.end());
        return v[v.size() / 2];
    };
    std::printf("manikin demo, %d cases x %d replicates: %.1f h of virtual time, %lld values stored; medians of 3\n", cases, replicates,
                work.virtual_s / 3600.0, work.values);
    std::printf("  demo                      %7.2f s wall  %7.2f s CPU\n", median(demo_wall), median(demo_cpu));
    std::printf("  floor (world + SQLite)    %7.2f s wall  %7.2f s CPU\n", median(floor_wall), median(floor_cpu));
    std::printf("  demo / floor, CPU         %7.2fx  (goal: at most 2.5x)\n", median(demo_cpu) / median(floor_cpu));
    fs::remove_all(dir);
    return 0;
}
