// Benchmark (not a test): the Recorder writing 1 000 000 samples into a fresh trial database
// (WAL, synchronous=NORMAL), beside its floor measured in the same run: raw SQLite, one
// thread, one prepared INSERT, transactions of 4096 rows, no queue at all.
#include <sqlite3.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <fmt/core.h>

#include "daemon/core/recorder/database.hpp"
#include "daemon/core/recorder/recorder.hpp"

namespace rec = manikind::recorder;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

constexpr std::int64_t total_rows = 1'000'000;
constexpr int zones = 35;
constexpr std::int64_t period_ns = 1'000'000'000;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Ids {
    std::int64_t trial = 0;
    std::vector<std::int64_t> channels;
};

// Row i: zone i % 35 at tick i / 35, as the manikin reports it.
rec::SampleRow make_row(const Ids& ids, std::int64_t i) {
    const std::int64_t tick = i / zones;
    return {ids.trial, ids.channels[static_cast<std::size_t>(i % zones)], tick * period_ns,
            1'700'000'000'000'000'000 + tick * period_ns, 20.0 + static_cast<double>(i % 997) * 0.01, 0};
}

// A fresh file with the schema, one trial and 35 channels; the connection is closed again.
Ids prepare(const fs::path& path) {
    fs::remove(path);
    auto db = rec::Database::open(path);
    Ids ids;
    const auto campaign = db.create_campaign("bench", "{}");
    ids.trial = db.create_trial(campaign, db.add_case(campaign, "case", "{}", 0), 1);
    const auto device = db.device_id("manikin", "bench", "none");
    for (int z = 1; z <= zones; ++z) ids.channels.push_back(db.channel_id(device, fmt::format("zone{:02}.heat_flux", z), "W/m2"));
    return ids;
}

std::uintmax_t file_bytes(const fs::path& path) {
    std::uintmax_t bytes = 0;
    for (const char* suffix : {"", "-wal", "-shm"}) {
        std::error_code ec;
        const auto n = fs::file_size(path.string() + suffix, ec);
        if (!ec) bytes += n;
    }
    return bytes;
}

void check(int rc, sqlite3* db, const char* what) {
    if (rc != SQLITE_OK && rc != SQLITE_DONE) {
        std::fprintf(stderr, "%s: %s\n", what, sqlite3_errmsg(db));
        std::exit(1);
    }
}

// The floor: the same pragmas as Database::open, the same INSERT, no queue, no thread.
double floor_rows_per_s(const fs::path& path, std::uintmax_t& bytes) {
    const Ids ids = prepare(path);
    sqlite3* db = nullptr;
    check(sqlite3_open(path.c_str(), &db), db, "open");
    check(sqlite3_exec(db, "PRAGMA journal_mode = WAL; PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON", nullptr,
                       nullptr, nullptr),
          db, "pragmas");
    sqlite3_stmt* insert = nullptr;
    check(sqlite3_prepare_v2(db,
                             "INSERT INTO samples (trial_id, channel_id, mono_ns, utc_ns, value, quality) VALUES (?, ?, ?, ?, ?, ?)",
                             -1, &insert, nullptr),
          db, "prepare");
    const auto t0 = Clock::now();
    for (std::int64_t i = 0; i < total_rows;) {
        check(sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr), db, "begin");
        for (const std::int64_t end = std::min(total_rows, i + 4096); i < end; ++i) {
            const auto r = make_row(ids, i);
            sqlite3_bind_int64(insert, 1, r.trial_id);
            sqlite3_bind_int64(insert, 2, r.channel_id);
            sqlite3_bind_int64(insert, 3, r.mono_ns);
            sqlite3_bind_int64(insert, 4, r.utc_ns);
            sqlite3_bind_double(insert, 5, r.value);
            sqlite3_bind_int64(insert, 6, r.quality);
            check(sqlite3_step(insert), db, "insert");
            sqlite3_reset(insert);
        }
        check(sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr), db, "commit");
    }
    const double s = seconds_since(t0);
    sqlite3_finalize(insert);
    sqlite3_close(db);
    bytes = file_bytes(path);
    return static_cast<double>(total_rows) / s;
}

struct RecorderRun {
    double rows_per_s = 0.0;
    double push_ns_per_row = 0.0;
    rec::RecorderStats stats;
    std::uintmax_t bytes = 0;
};

RecorderRun recorder_run(const fs::path& path, rec::Durability durability = rec::Durability::process) {
    const Ids ids = prepare(path);
    RecorderRun run;
    {
        rec::RecorderOptions options;
        options.queue_capacity = 1 << 20;  // more than total_rows: this measures throughput, not drops
        options.durability = durability;
        rec::Recorder recorder(path, options);
        double push_s = 0.0;
        const auto t0 = Clock::now();
        std::thread producer([&] {
            const auto p0 = Clock::now();
            for (std::int64_t i = 0; i < total_rows; ++i) recorder.push(make_row(ids, i));
            push_s = seconds_since(p0);
        });
        producer.join();
        recorder.flush();
        run.rows_per_s = static_cast<double>(total_rows) / seconds_since(t0);
        run.push_ns_per_row = push_s * 1e9 / static_cast<double>(total_rows);
        run.stats = recorder.stats();
    }
    run.bytes = file_bytes(path);
    return run;
}

}  // namespace

int main() {
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-bench-recorder-{}", ::getpid());
    fs::remove_all(dir);
    fs::create_directories(dir);
    std::printf("%lld rows (%d channels), fresh file each run in %s, SQLite %s, WAL, synchronous=NORMAL\n",
                static_cast<long long>(total_rows), zones, dir.c_str(), sqlite3_libversion());

    const int repeats = 3;
    double best_floor = 0.0;
    std::uintmax_t floor_bytes = 0;
    RecorderRun best, best_power;
    double worst_commit_ms = 0.0, worst_power_commit_ms = 0.0;
    std::uint64_t dropped = 0;
    for (int i = 0; i < repeats; ++i) {  // interleaved, so a slow moment of the disk hits both
        std::uintmax_t bytes = 0;
        best_floor = std::max(best_floor, floor_rows_per_s(dir / "floor.db", bytes));
        floor_bytes = bytes;
        const auto r = recorder_run(dir / "recorder.db");
        if (r.rows_per_s > best.rows_per_s) best = r;
        worst_commit_ms = std::max(worst_commit_ms, r.stats.max_commit_ms);
        dropped += r.stats.dropped;
        // [recorder] durability = "power": synchronous = FULL, a disk sync per commit.
        const auto p = recorder_run(dir / "recorder-power.db", rec::Durability::power);
        if (p.rows_per_s > best_power.rows_per_s) best_power = p;
        worst_power_commit_ms = std::max(worst_power_commit_ms, p.stats.max_commit_ms);
    }
    std::printf("floor    raw prepared INSERT, 4096 rows/transaction, one thread  %9.0f rows/s\n", best_floor);
    std::printf("recorder push from a producer thread, flush (end to end)       %9.0f rows/s  ratio %.2f of floor\n",
                best.rows_per_s, best.rows_per_s / best_floor);
    std::printf("recorder push alone %.0f ns/row; %llu batches; max commit %.1f ms (worst of %d runs); dropped %llu\n",
                best.push_ns_per_row, static_cast<unsigned long long>(best.stats.batches), worst_commit_ms, repeats,
                static_cast<unsigned long long>(dropped));
    std::printf("recorder durability=power (synchronous=FULL)                %9.0f rows/s  ratio %.2f of floor; "
                "max commit %.1f ms (%llu batches)\n",
                best_power.rows_per_s, best_power.rows_per_s / best_floor, worst_power_commit_ms,
                static_cast<unsigned long long>(best_power.stats.batches));
    std::printf("file size per million rows: recorder %.1f MB, floor %.1f MB (after close, WAL checkpointed)\n",
                static_cast<double>(best.bytes) / 1e6 * 1e6 / static_cast<double>(total_rows),
                static_cast<double>(floor_bytes) / 1e6 * 1e6 / static_cast<double>(total_rows));
    std::printf("best of %d runs each\n", repeats);
    fs::remove_all(dir);
    return 0;
}
