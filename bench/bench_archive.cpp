// Benchmark (not a test): forwarding to the PostgreSQL archive (issue 19, docs/archive.md), on a
// PostgreSQL 15 server started for the run (as tests/archive/pg_server.hpp does; fsync off, so
// the figures are the protocol's and the server's CPU, not this disk's).
//
// 1. Rows per second into the archive's sample_rows table, three ways, interleaved, each into a
//    fresh database, from the same recorder file of 400 000 samples (35 channels, one done trial):
//    - push():   COPY straight into sample_rows (integer keys; rows past the progress key were
//                never committed), 50 000 rows a transaction (what `manikin archive push` and the
//                daemon do);
//    - inserts:  one prepared INSERT ... ON CONFLICT DO NOTHING per row, same transactions;
//    - floor:    the same rows read from the same SQLite file, written as COPY text and copied
//                straight into a table with no key, index or foreign key (what the server cannot
//                beat for this data). Inside its timer, as push has inside its own: the
//                connection, the table's creation, the SQLite reading and the text (issue 36:
//                the text had been built before the floor's timer started).
//    Then what each key and check costs: the same rows as COPY text built before the timers, into
//    a table with no key, an integer key, an integer key and a foreign key, through a staging
//    table with ON CONFLICT, and with the old key of three text columns.
// 2. The lag behind acquisition in real time: a Recorder fed at the simulated lab's rate times
//    ten (390 rows/s), committing every second as the daemon does, and the daemon's forwarding
//    thread (BackgroundForwarder) at its default 5-s interval and at 1 s; every 250 ms, now minus
//    the newest sample's time in the archive. Medians and maxima over 30 s.
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
#include <sqlite3.h>

#include "archive/background.hpp"
#include "archive/forwarder.hpp"
#include "archive/pg.hpp"
#include "archive/pg_schema.hpp"
#include "store/database.hpp"
#include "store/recorder.hpp"
#include "tests/archive/pg_server.hpp"

namespace rec = manikind::recorder;
namespace ar = manikind::archive;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

constexpr std::int64_t total_rows = 400'000;
constexpr int channels = 35;
constexpr std::int64_t period_ns = 5'000'000'000;  // the manikin's 5-s reports
constexpr std::size_t chunk_rows = 50'000;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v[v.size() / 2];
}

std::int64_t utc_now_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

struct Source {
    std::int64_t trial = 0;
    std::vector<std::int64_t> channel_ids;
};

Source make_source(const fs::path& path, bool done) {
    fs::remove(path);
    auto db = rec::Database::open(path);
    Source s;
    const auto campaign = db.create_campaign("bench", "{}");
    s.trial = db.create_trial(campaign, db.add_case(campaign, "case 1", "{\"id\": 1}", 0), 1);
    const auto device = db.device_id("manikin", "can", "vcan0");
    for (int z = 1; z <= channels; ++z)
        s.channel_ids.push_back(db.channel_id(device, fmt::format("zone{:02}.heat_flux_w_m2", z), "W/m2"));
    if (done) {
        std::vector<rec::SampleRow> rows;
        for (std::int64_t i = 0; i < total_rows; ++i) {
            const std::int64_t tick = i / channels;
            rows.push_back({s.trial, s.channel_ids[static_cast<std::size_t>(i % channels)], tick * period_ns,
                            1'790'000'000'000'000'000 + tick * period_ns, 40.0 + static_cast<double>(i % 997) * 0.013, 0});
        }
        db.insert_samples(rows);
        db.set_trial_state(s.trial, "done", "", utc_now_ns());
    }
    return s;
}

std::string fresh_database(const std::string& admin_conninfo, const std::string& name) {
    auto pg = ar::PgConnection::connect(admin_conninfo);
    pg.exec("DROP DATABASE IF EXISTS " + name);
    pg.exec("CREATE DATABASE " + name);
    return admin_conninfo.substr(0, admin_conninfo.rfind("dbname=")) + "dbname=" + name;
}

double run_push(const std::string& conninfo, const fs::path& db) {
    ar::PushOptions o;
    o.chunk_rows = chunk_rows;
    const auto t0 = Clock::now();
    const auto r = ar::push(db, conninfo, "bench-lab", o);
    const double s = seconds_since(t0);
    if (r.samples.added != total_rows) throw std::runtime_error("push added " + std::to_string(r.samples.added));
    return static_cast<double>(total_rows) / s;
}

// Per-row prepared INSERTs into the archive's own sample_rows table (after a push has created the
// schema, the lab, the trial and the channels, with its samples deleted again).
double run_inserts(const std::string& conninfo, const fs::path& db) {
    ar::PushOptions o;
    o.chunk_rows = chunk_rows;
    (void)ar::push(db, conninfo, "bench-lab", o);
    auto pg = ar::PgConnection::connect(conninfo);
    const std::string trial_key = pg.exec("SELECT trial_key FROM trials").text(0, 0);
    std::vector<std::string> channel_keys;
    for (int z = 1; z <= channels; ++z)
        channel_keys.push_back(
            pg.exec("SELECT channel_key FROM channels WHERE channel = $1", {fmt::format("zone{:02}.heat_flux_w_m2", z)}).text(0, 0));
    pg.exec("DELETE FROM sample_rows");
    pg.exec("VACUUM sample_rows");
    PQclear(PQprepare(pg.raw(), "ins",
                      "INSERT INTO sample_rows (trial_key, mono_ns, channel_key, utc_ns, value, quality)"
                      " VALUES ($1, $2, $3, $4, $5, $6) ON CONFLICT DO NOTHING",
                      6, nullptr));
    const auto t0 = Clock::now();
    for (std::int64_t first = 0; first < total_rows; first += static_cast<std::int64_t>(chunk_rows)) {
        pg.exec("BEGIN");
        for (std::int64_t i = first; i < std::min<std::int64_t>(total_rows, first + static_cast<std::int64_t>(chunk_rows));
             ++i) {
            const std::int64_t tick = i / channels;
            const std::string& channel = channel_keys[static_cast<std::size_t>(i % channels)];
            const std::string mono = std::to_string(tick * period_ns);
            const std::string utc = std::to_string(1'790'000'000'000'000'000 + tick * period_ns);
            const std::string value = fmt::format("{}", 40.0 + static_cast<double>(i % 997) * 0.013);
            const char* params[] = {trial_key.c_str(), mono.c_str(), channel.c_str(), utc.c_str(), value.c_str(), "0"};
            PGresult* r = PQexecPrepared(pg.raw(), "ins", 6, params, nullptr, nullptr, 0);
            const bool ok = PQresultStatus(r) == PGRES_COMMAND_OK;
            PQclear(r);
            if (!ok) throw std::runtime_error(std::string("insert failed: ") + PQerrorMessage(pg.raw()));
        }
        pg.exec("COMMIT");
    }
    return static_cast<double>(total_rows) / seconds_since(t0);
}

// What each key and check costs on the server: the same rows, as COPY text built before the
// timer (integer keys, or the names the archive keyed on before schema v5), copied in chunks of
// chunk_rows into a table of each kind. Rows per second.
struct KeyCosts {
    double keyless = 0, integer_key = 0, integer_key_fk = 0, staged_on_conflict = 0, text_key = 0;
};
KeyCosts run_key_costs(const std::string& conninfo) {
    auto pg = ar::PgConnection::connect(conninfo);
    pg.exec("CREATE TABLE parent (trial_key integer PRIMARY KEY)");
    pg.exec("INSERT INTO parent VALUES (1)");
    std::vector<std::string> int_chunks, text_chunks;
    for (std::int64_t first = 0; first < total_rows; first += static_cast<std::int64_t>(chunk_rows)) {
        std::string ints, texts;
        for (std::int64_t i = first; i < std::min<std::int64_t>(total_rows, first + static_cast<std::int64_t>(chunk_rows)); ++i) {
            const std::int64_t tick = i / channels, mono = tick * period_ns, utc = 1'790'000'000'000'000'000 + tick * period_ns;
            const double value = 40.0 + static_cast<double>(i % 997) * 0.013;
            ints += fmt::format("1\t{}\t{}\t{}\t{}\t0\n", mono, i % channels + 1, utc, value);
            texts += fmt::format("0123456789abcdef0123456789abcdef\tmanikin\tzone{:02}.heat_flux_w_m2\t{}\t{}\t{}\t0\n", i % channels + 1,
                                 mono, utc, value);
        }
        int_chunks.push_back(std::move(ints));
        text_chunks.push_back(std::move(texts));
    }
    const auto timed = [&](const std::string& ddl, const std::string& copy, const std::vector<std::string>& chunks,
                           const std::string& after = {}) {
        pg.exec("DROP TABLE IF EXISTS t");
        pg.exec("DROP TABLE IF EXISTS staging");
        pg.exec(ddl);
        if (!after.empty()) pg.exec("CREATE TEMP TABLE staging (LIKE t) ON COMMIT DELETE ROWS");
        const auto t0 = Clock::now();
        for (const auto& chunk : chunks) {
            pg.exec("BEGIN");
            pg.copy_in(copy, chunk);
            if (!after.empty()) pg.exec(after);
            pg.exec("COMMIT");
        }
        return static_cast<double>(total_rows) / seconds_since(t0);
    };
    const std::string cols = "(trial_key integer NOT NULL, mono_ns bigint NOT NULL, channel_key integer NOT NULL, utc_ns bigint NOT NULL,"
                             " value double precision, quality smallint NOT NULL";
    KeyCosts k;
    k.keyless = timed("CREATE TABLE t " + cols + ")", "COPY t FROM STDIN", int_chunks);
    k.integer_key = timed("CREATE TABLE t " + cols + ", PRIMARY KEY (trial_key, mono_ns, channel_key))", "COPY t FROM STDIN", int_chunks);
    k.integer_key_fk = timed("CREATE TABLE t " + cols + ", PRIMARY KEY (trial_key, mono_ns, channel_key), FOREIGN KEY (trial_key) REFERENCES parent)",
                             "COPY t FROM STDIN", int_chunks);
    k.staged_on_conflict = timed("CREATE TABLE t " + cols + ", PRIMARY KEY (trial_key, mono_ns, channel_key))", "COPY staging FROM STDIN",
                                 int_chunks, "INSERT INTO t SELECT * FROM staging ON CONFLICT DO NOTHING");
    k.text_key = timed("CREATE TABLE t (trial_uuid text NOT NULL, device text NOT NULL, channel text NOT NULL, mono_ns bigint NOT NULL,"
                       " utc_ns bigint NOT NULL, value double precision, quality smallint NOT NULL,"
                       " PRIMARY KEY (trial_uuid, device, channel, mono_ns))",
                       "COPY t FROM STDIN", text_chunks);
    return k;
}

double run_floor(const std::string& conninfo, const fs::path& db) {
    const auto t0 = Clock::now();
    auto pg = ar::PgConnection::connect(conninfo);
    pg.exec("CREATE TABLE plain (device text, channel text, mono_ns bigint, utc_ns bigint, value double precision,"
            " quality smallint)");
    sqlite3* src = nullptr;
    if (sqlite3_open_v2(db.c_str(), &src, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) throw std::runtime_error("floor: cannot open the source");
    sqlite3_stmt* q = nullptr;
    sqlite3_prepare_v2(src,
                       "SELECT d.name, c.name, s.mono_ns, s.utc_ns, s.value, s.quality FROM samples s"
                       " JOIN channels c ON c.id = s.channel_id JOIN devices d ON d.id = c.device_id ORDER BY s.id",
                       -1, &q, nullptr);
    std::string data;
    std::int64_t rows = 0;
    auto flush = [&] {
        pg.exec("BEGIN");
        pg.copy_in("COPY plain FROM STDIN", data);
        pg.exec("COMMIT");
        data.clear();
    };
    while (sqlite3_step(q) == SQLITE_ROW) {
        data += reinterpret_cast<const char*>(sqlite3_column_text(q, 0));
        data += '\t';
        data += reinterpret_cast<const char*>(sqlite3_column_text(q, 1));
        data += fmt::format("\t{}\t{}\t{}\t{}\n", sqlite3_column_int64(q, 2), sqlite3_column_int64(q, 3), sqlite3_column_double(q, 4),
                            sqlite3_column_int64(q, 5));
        if (++rows % static_cast<std::int64_t>(chunk_rows) == 0) flush();
    }
    if (!data.empty()) flush();
    sqlite3_finalize(q);
    sqlite3_close(src);
    if (rows != total_rows) throw std::runtime_error("floor read " + std::to_string(rows) + " rows");
    return static_cast<double>(total_rows) / seconds_since(t0);
}

struct Lag {
    double median_s = 0.0, max_s = 0.0;
};

// A recorder fed in real time, the forwarding thread beside it, the archive polled for the newest row.
Lag run_lag(const std::string& conninfo, const fs::path& db, std::chrono::milliseconds interval) {
    const Source s = make_source(db, false);
    rec::RecorderOptions ro;
    ro.max_batch_delay = std::chrono::milliseconds(1000);  // the daemon's default commit interval
    rec::Recorder recorder(db, ro);
    ar::ForwardingOptions fo;
    fo.database = db;
    fo.conninfo = conninfo;
    fo.lab_id = "lag-lab";
    fo.interval = interval;
    ar::BackgroundForwarder forwarder(fo, {});
    auto pg = ar::PgConnection::connect(conninfo);
    std::vector<double> lags;
    const auto start = Clock::now();
    const auto mono0 = Clock::now();
    auto next_feed = Clock::now();
    auto next_poll = Clock::now() + std::chrono::seconds(5);  // after the first pass has made the schema
    while (seconds_since(start) < 35.0) {
        const auto now = Clock::now();
        if (now >= next_feed) {  // 39 rows every 100 ms: 390 rows/s
            const std::int64_t mono = std::chrono::duration_cast<std::chrono::nanoseconds>(now - mono0).count();
            const std::int64_t utc = utc_now_ns();
            for (int c = 0; c < 39; ++c)
                recorder.push({s.trial, s.channel_ids[static_cast<std::size_t>(c % channels)], mono + c, utc, 1.0 * c, 0});
            next_feed += std::chrono::milliseconds(100);
        }
        if (now >= next_poll) {
            try {
                auto r = pg.exec("SELECT max(utc_ns) FROM samples");
                if (!r.is_null(0, 0)) lags.push_back(static_cast<double>(utc_now_ns() - r.int64(0, 0)) * 1e-9);
            } catch (const std::exception&) {
                // The schema may not exist yet.
            }
            next_poll += std::chrono::milliseconds(250);
        }
        std::this_thread::sleep_until(std::min(next_feed, next_poll));
    }
    forwarder.stop();
    Lag l;
    l.median_s = median(lags);
    l.max_s = lags.empty() ? 0.0 : *std::max_element(lags.begin(), lags.end());
    return l;
}

}  // namespace

int main() {
    if (!manikind::test::PgServer::available()) {
        std::printf("bench_archive: skipped, no PostgreSQL 15 server binaries (scripts/setup.sh --tests installs them)\n");
        return 0;
    }
    manikind::test::PgServer server;
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-bench-archive-{}", ::getpid());
    fs::create_directories(dir);
    const fs::path source = dir / "source.db";
    make_source(source, true);

    std::vector<double> push_rps, insert_rps, floor_rps;
    std::vector<KeyCosts> costs;
    for (int run = 0; run < 3; ++run) {
        push_rps.push_back(run_push(fresh_database(server.conninfo(), fmt::format("push{}", run)), source));
        insert_rps.push_back(run_inserts(fresh_database(server.conninfo(), fmt::format("ins{}", run)), source));
        floor_rps.push_back(run_floor(fresh_database(server.conninfo(), fmt::format("floor{}", run)), source));
        costs.push_back(run_key_costs(fresh_database(server.conninfo(), fmt::format("keys{}", run))));
        std::printf("run %d: push %.0f rows/s, per-row INSERT %.0f rows/s, COPY floor %.0f rows/s\n", run + 1,
                    push_rps.back(), insert_rps.back(), floor_rps.back());
        std::fflush(stdout);
    }
    std::printf("\n%lld samples, %d channels, %zu rows per transaction; medians of 3 interleaved runs:\n",
                static_cast<long long>(total_rows), channels, chunk_rows);
    std::printf("  push (plain COPY into sample_rows past the progress key)  %9.0f rows/s  %.2f of the floor\n", median(push_rps),
                median(push_rps) / median(floor_rps));
    std::printf("  per-row prepared INSERT ON CONFLICT                        %9.0f rows/s  %.2f of the floor\n", median(insert_rps),
                median(insert_rps) / median(floor_rps));
    std::printf("  floor: SQLite read + COPY into a table with no key         %9.0f rows/s\n", median(floor_rps));
    std::printf("  push / per-row INSERT: %.1fx\n\n", median(push_rps) / median(insert_rps));
    const auto med = [&](double KeyCosts::*field) {
        std::vector<double> v;
        for (const auto& c : costs) v.push_back(c.*field);
        return median(v);
    };
    const double keyless = med(&KeyCosts::keyless);
    std::printf("what each key and check costs on the server (the same COPY text built before the timers; medians of 3):\n");
    const auto line = [&](const char* what, double rps) {
        std::printf("  %-62s %9.0f rows/s  %+6.2f s per million rows\n", what, rps, 1e6 / rps - 1e6 / keyless);
    };
    std::printf("  %-62s %9.0f rows/s\n", "COPY, integer columns, no key", keyless);
    line("COPY, integer key (trial, mono_ns, channel): what a push does", med(&KeyCosts::integer_key));
    line("  + a foreign key to trials checked per row", med(&KeyCosts::integer_key_fk));
    line("COPY into staging, INSERT ... ON CONFLICT DO NOTHING (re-send)", med(&KeyCosts::staged_on_conflict));
    line("COPY, key of three text columns (the archive before schema v5)", med(&KeyCosts::text_key));
    std::printf("\n");

    for (const auto interval : {std::chrono::milliseconds(5000), std::chrono::milliseconds(1000)}) {
        const auto lag = run_lag(fresh_database(server.conninfo(), fmt::format("lag{}", interval.count())),
                                 dir / fmt::format("lag{}.db", interval.count()), interval);
        std::printf("real-time lag at 390 rows/s, commit every 1 s, forwarding every %.0f s: median %.1f s, max %.1f s "
                    "(30 s)\n",
                    static_cast<double>(interval.count()) / 1000.0, lag.median_s, lag.max_s);
        std::fflush(stdout);
    }
    fs::remove_all(dir);
    return 0;
}
