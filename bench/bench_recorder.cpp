// Benchmark (not a test): the Recorder writing 1 000 000 samples into a fresh trial database
// (WAL, synchronous=NORMAL), beside two floors measured in the same run: raw C SQLite, one
// thread, one prepared INSERT, transactions of 4096 rows, no queue at all, into a plain
// append-only table and into our schema. Then the bytes written per byte stored at the lab's
// rate for several commit intervals, beside raw C SQLite on the plain table.
#include <sqlite3.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

#include <fmt/core.h>

#include "store/database.hpp"
#include "store/recorder.hpp"

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

// A fresh file with the schema, one trial and `channels` channels; the connection is closed again.
Ids prepare(const fs::path& path, int channels = zones, rec::Journal journal = rec::Journal::wal) {
    for (const char* suffix : {"", "-wal", "-shm", "-journal"}) fs::remove(path.string() + suffix);
    auto db = rec::Database::open(path, rec::Durability::process, journal);
    Ids ids;
    const auto campaign = db.create_campaign("bench", "{}");
    ids.trial = db.create_trial(campaign, db.add_case(campaign, "case", "{}", 0), 1);
    const auto device = db.device_id("manikin", "bench", "none");
    for (int z = 1; z <= channels; ++z) ids.channels.push_back(db.channel_id(device, fmt::format("zone{:02}.heat_flux", z), "W/m2"));
    return ids;
}

std::uintmax_t file_bytes(const fs::path& path) {
    std::uintmax_t bytes = 0;
    for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
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

// The two floors: raw C SQLite, one thread, one prepared INSERT, no queue. `plain`: an
// append-only rowid table with no key, no constraint and foreign keys off (what SQLite can do
// at all); otherwise our schema with Database::open's pragmas, foreign keys checked by SQLite,
// each row given its id in the trial's range (what the schema costs).
constexpr const char* plain_table_sql =
    "CREATE TABLE plain_samples (trial_id INTEGER, channel_id INTEGER, mono_ns INTEGER, utc_ns INTEGER, value REAL, quality INTEGER)";

sqlite3* open_floor(const fs::path& path, bool plain, Ids& ids, sqlite3_stmt*& insert, rec::Journal journal = rec::Journal::wal) {
    sqlite3* db = nullptr;
    if (plain) {
        for (const char* suffix : {"", "-wal", "-shm", "-journal"}) fs::remove(path.string() + suffix);
        ids = Ids{1, {}};
        for (int z = 1; z <= 157; ++z) ids.channels.push_back(z);
        check(sqlite3_open(path.c_str(), &db), db, "open");
        check(sqlite3_exec(db,
                           journal == rec::Journal::wal ? "PRAGMA journal_mode = WAL; PRAGMA synchronous = NORMAL"
                                                        : "PRAGMA journal_mode = TRUNCATE; PRAGMA synchronous = NORMAL",
                           nullptr, nullptr, nullptr),
              db, "pragmas");
        check(sqlite3_exec(db, plain_table_sql, nullptr, nullptr, nullptr), db, "create");
    } else {
        ids = prepare(path);
        check(sqlite3_open(path.c_str(), &db), db, "open");
        check(sqlite3_exec(db, "PRAGMA journal_mode = WAL; PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON", nullptr,
                           nullptr, nullptr),
              db, "pragmas");
    }
    check(sqlite3_prepare_v2(db,
                             plain ? "INSERT INTO plain_samples (trial_id, channel_id, mono_ns, utc_ns, value, quality) VALUES (?, ?, ?, ?, ?, ?)"
                                   : "INSERT INTO samples (trial_id, channel_id, mono_ns, utc_ns, value, quality, id)"
                                     " VALUES (?, ?, ?, ?, ?, ?, ?)",
                             -1, &insert, nullptr),
          db, "prepare");
    return db;
}

// `id`: our schema's rowid, (trial << 36) + n (version 8); 0 for the plain table, which has none.
void insert_row(sqlite3* db, sqlite3_stmt* insert, const rec::SampleRow& r, std::int64_t id = 0) {
    if (id != 0) sqlite3_bind_int64(insert, 7, id);
    sqlite3_bind_int64(insert, 1, r.trial_id);
    sqlite3_bind_int64(insert, 2, r.channel_id);
    sqlite3_bind_int64(insert, 3, r.mono_ns);
    sqlite3_bind_int64(insert, 4, r.utc_ns);
    sqlite3_bind_double(insert, 5, r.value);
    sqlite3_bind_int64(insert, 6, r.quality);
    check(sqlite3_step(insert), db, "insert");
    sqlite3_reset(insert);
}

double floor_rows_per_s(const fs::path& path, std::uintmax_t& bytes, bool plain) {
    Ids ids;
    sqlite3_stmt* insert = nullptr;
    sqlite3* db = open_floor(path, plain, ids, insert);
    const auto t0 = Clock::now();
    for (std::int64_t i = 0; i < total_rows;) {
        check(sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr), db, "begin");
        for (const std::int64_t end = std::min(total_rows, i + 4096); i < end; ++i)
            insert_row(db, insert, make_row(ids, i), plain ? 0 : rec::trial_id_begin(ids.trial) + i);
        check(sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr), db, "commit");
    }
    const double s = seconds_since(t0);
    sqlite3_finalize(insert);
    sqlite3_close(db);
    bytes = file_bytes(path);
    return static_cast<double>(total_rows) / s;
}

// The end-to-end floor on the recorder's two threads (issue 36: a one-thread floor bounded a
// two-thread run): a producer thread hands batches of 4096 rows over a mutex and a condition
// variable to a writer thread, which appends each batch to our schema with raw C SQLite in one
// transaction. The least a producer-and-writer pipeline can do for the same rows and commits:
// foreign keys off, as the recorder's connection has them (it checks trial and channel itself,
// once per batch), so the floor does no work the recorder skips.
double floor_two_threads_rows_per_s(const fs::path& path) {
    Ids ids;
    sqlite3_stmt* insert = nullptr;
    sqlite3* db = open_floor(path, false, ids, insert);
    check(sqlite3_exec(db, "PRAGMA foreign_keys = OFF", nullptr, nullptr, nullptr), db, "foreign keys off");
    std::mutex m;
    std::condition_variable cv;
    std::vector<rec::SampleRow> ready;
    bool done = false;
    const auto t0 = Clock::now();
    std::thread producer([&] {
        std::vector<rec::SampleRow> batch;
        for (std::int64_t i = 0; i < total_rows; ++i) {
            batch.push_back(make_row(ids, i));
            if (batch.size() == 4096 || i + 1 == total_rows) {
                std::unique_lock lk(m);
                cv.wait(lk, [&] { return ready.empty(); });
                ready.swap(batch);
                batch.clear();
                cv.notify_all();
            }
        }
        std::lock_guard lk(m);
        done = true;
        cv.notify_all();
    });
    std::int64_t written = 0;
    for (;;) {
        std::vector<rec::SampleRow> batch;
        {
            std::unique_lock lk(m);
            cv.wait(lk, [&] { return !ready.empty() || done; });
            if (ready.empty() && done) break;
            batch.swap(ready);
            cv.notify_all();
        }
        check(sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr), db, "begin");
        for (const auto& r : batch) insert_row(db, insert, r, rec::trial_id_begin(ids.trial) + written++);
        check(sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr), db, "commit");
    }
    producer.join();
    const double s = seconds_since(t0);
    sqlite3_finalize(insert);
    sqlite3_close(db);
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

// Bytes this process has passed to write(2) and friends so far (the WAL, the checkpoints, the
// database): what reaches the page cache and, sooner or later, the disk.
std::int64_t written_bytes() {
    std::ifstream io("/proc/self/io");
    std::string key;
    std::int64_t value = 0;
    while (io >> key >> value)
        if (key == "wchar:") return value;
    return -1;
}

// The simulated lab's rate: 157 channels, each read every 4 s (39 rows/s), for one 75-min trial,
// in time order, committed every `commit_interval_s`.
constexpr int lab_channels = 157;
constexpr double lab_channel_period_s = 4.0;
constexpr double lab_trial_s = 75.0 * 60.0;

template <typename Push, typename Commit>
std::int64_t feed_lab_trial(const Ids& ids, double commit_interval_s, Push push, Commit commit) {
    const auto rows = static_cast<std::int64_t>(lab_trial_s / lab_channel_period_s * lab_channels);
    const double row_spacing_s = lab_channel_period_s / lab_channels;
    double next_commit_s = commit_interval_s;
    for (std::int64_t i = 0; i < rows; ++i) {
        const double t_s = static_cast<double>(i) * row_spacing_s;
        if (t_s >= next_commit_s) {
            commit();
            next_commit_s += commit_interval_s;
        }
        const auto mono_ns = static_cast<std::int64_t>(t_s * 1e9);
        push(rec::SampleRow{ids.trial, ids.channels[static_cast<std::size_t>(i % lab_channels)], mono_ns,
                            1'700'000'000'000'000'000 + mono_ns, 20.0 + static_cast<double>(i % 997) * 0.0137, 0});
    }
    commit();
    return rows;
}

struct Amplification {
    double written_mb = 0.0, stored_mb = 0.0;
    std::int64_t rows = 0;
    double ratio() const { return written_mb / stored_mb; }
};

// The Recorder at the lab's rate, with its crash ring (the default): flush() stands in for the
// commit timer, so the bench does not wait 75 min.
Amplification recorder_amplification(const fs::path& path, double commit_interval_s, rec::Journal journal) {
    const Ids ids = prepare(path, lab_channels, journal);
    Amplification a;
    const std::int64_t before = written_bytes();
    {
        rec::RecorderOptions options;
        options.journal = journal;
        options.max_batch_delay = std::chrono::minutes(10);  // commits only at flush()
        rec::Recorder recorder(path, options);
        a.rows = feed_lab_trial(ids, commit_interval_s, [&](const rec::SampleRow& r) { recorder.push(r); },
                                [&] { recorder.flush(); });
    }  // closing checkpoints the WAL into the database and removes it
    a.written_mb = static_cast<double>(written_bytes() - before) / 1e6;
    a.stored_mb = static_cast<double>(file_bytes(path)) / 1e6;
    return a;
}

// The floor: raw C SQLite appending the same rows to the plain table, same commits.
Amplification plain_amplification(const fs::path& path, double commit_interval_s, rec::Journal journal) {
    Ids ids;
    sqlite3_stmt* insert = nullptr;
    sqlite3* db = open_floor(path, true, ids, insert, journal);
    Amplification a;
    const std::int64_t before = written_bytes();
    bool open = false;
    a.rows = feed_lab_trial(
        ids, commit_interval_s,
        [&](const rec::SampleRow& r) {
            if (!open) check(sqlite3_exec(db, "BEGIN", nullptr, nullptr, nullptr), db, "begin");
            open = true;
            insert_row(db, insert, r);
        },
        [&] {
            if (open) check(sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr), db, "commit");
            open = false;
        });
    sqlite3_finalize(insert);
    sqlite3_close(db);
    a.written_mb = static_cast<double>(written_bytes() - before) / 1e6;
    a.stored_mb = static_cast<double>(file_bytes(path)) / 1e6;
    return a;
}

double median(std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
    return v[v.size() / 2];
}

}  // namespace

int main() {
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-bench-recorder-{}", ::getpid());
    fs::remove_all(dir);
    fs::create_directories(dir);
    std::printf("%lld rows (%d channels), fresh file each run in %s, SQLite %s, WAL, synchronous=NORMAL\n",
                static_cast<long long>(total_rows), zones, dir.c_str(), sqlite3_libversion());

    const int repeats = 5;
    std::vector<double> plain_runs, schema_runs, two_thread_runs, recorder_runs, power_runs, push_ns;
    std::uintmax_t plain_bytes = 0, schema_bytes = 0, recorder_bytes = 0;
    double worst_commit_ms = 0.0, worst_power_commit_ms = 0.0;
    std::uint64_t dropped = 0, batches = 0, power_batches = 0;
    for (int i = 0; i < repeats; ++i) {  // interleaved, so a slow moment of the disk hits all
        plain_runs.push_back(floor_rows_per_s(dir / "plain.db", plain_bytes, true));
        schema_runs.push_back(floor_rows_per_s(dir / "floor.db", schema_bytes, false));
        two_thread_runs.push_back(floor_two_threads_rows_per_s(dir / "floor2.db"));
        const auto r = recorder_run(dir / "recorder.db");
        recorder_runs.push_back(r.rows_per_s);
        push_ns.push_back(r.push_ns_per_row);
        recorder_bytes = r.bytes;
        batches = r.stats.batches;
        worst_commit_ms = std::max(worst_commit_ms, r.stats.max_commit_ms);
        dropped += r.stats.dropped;
        // [recorder] durability = "power": synchronous = FULL, a disk sync per commit.
        const auto p = recorder_run(dir / "recorder-power.db", rec::Durability::power);
        power_runs.push_back(p.rows_per_s);
        power_batches = p.stats.batches;
        worst_power_commit_ms = std::max(worst_power_commit_ms, p.stats.max_commit_ms);
    }
    const double plain = median(plain_runs), schema = median(schema_runs), recorder = median(recorder_runs),
                 power = median(power_runs);
    std::printf("throughput, medians of %d interleaved runs (rows/s):\n", repeats);
    std::printf("  floor    raw C SQLite, plain append-only table, no key, 4096 rows/transaction %9.0f\n", plain);
    std::printf("  floor    raw C SQLite, our schema (id range per trial, FKs), same transactions  %9.0f  %.2f of plain\n", schema,
                schema / plain);
    const double two_threads = median(two_thread_runs);
    std::printf("  floor    raw C SQLite, our schema, producer thread + writer thread (handed over) %9.0f  %.2f of plain\n",
                two_threads, two_threads / plain);
    std::printf("  recorder push from a producer thread, flush (end to end)                      %9.0f  %.2f of plain, %.2f of the two-thread floor\n",
                recorder, recorder / plain, recorder / two_threads);
    std::printf("  recorder durability=power (synchronous=FULL)                                  %9.0f  %.2f of plain; max commit %.1f ms (%llu batches)\n",
                power, power / plain, worst_power_commit_ms, static_cast<unsigned long long>(power_batches));
    std::printf("  recorder push alone %.0f ns/row (median); %llu batches; max commit %.1f ms (worst of %d); dropped %llu\n",
                median(push_ns), static_cast<unsigned long long>(batches), worst_commit_ms, repeats,
                static_cast<unsigned long long>(dropped));
    std::printf("  file size per million rows: plain %.1f MB, our schema %.1f MB, recorder %.1f MB (after close)\n",
                static_cast<double>(plain_bytes) * 1e6 / static_cast<double>(total_rows) / 1e6,
                static_cast<double>(schema_bytes) * 1e6 / static_cast<double>(total_rows) / 1e6,
                static_cast<double>(recorder_bytes) * 1e6 / static_cast<double>(total_rows) / 1e6);

    std::printf("\nwrite amplification at the lab's rate (%d channels every %.0f s, one %.0f-min trial):\n"
                "bytes passed to write() by the process per byte of the closed database (median of 3)\n",
                lab_channels, lab_channel_period_s, lab_trial_s / 60.0);
    std::printf("                 [recorder] journal = \"wal\" (default)        journal = \"rollback\"\n");
    std::printf("  commit every   recorder   floor: raw C, plain table      recorder   floor: raw C, plain table\n");
    for (const double interval_s : {1.0, 5.0, 10.0, 30.0, 60.0}) {
        std::printf("  %5.1f s", interval_s);
        for (const rec::Journal journal : {rec::Journal::wal, rec::Journal::rollback}) {
            std::vector<double> ours, floor;
            Amplification last_ours, last_floor;
            for (int i = 0; i < 3; ++i) {
                last_ours = recorder_amplification(dir / "amp-recorder.db", interval_s, journal);
                last_floor = plain_amplification(dir / "amp-plain.db", interval_s, journal);
                ours.push_back(last_ours.ratio());
                floor.push_back(last_floor.ratio());
            }
            std::printf("       %6.2fx   %6.2fx (%.1f / %.1f MB stored)", median(ours), median(floor), last_ours.stored_mb,
                        last_floor.stored_mb);
        }
        std::printf("\n");
    }
    std::printf("  (WAL writes every page twice, to the WAL and at the checkpoint: 2x is its floor. A rollback\n"
                "   journal writes new pages once but saves each changed page first, so short commits cost more)\n");
    std::printf("  (the recorder's crash ring keeps each uncommitted row in shared memory, 48 bytes a row:\n"
                "   stores to a mapping, not write(), and no disk behind them)\n");
    fs::remove_all(dir);
    return 0;
}
