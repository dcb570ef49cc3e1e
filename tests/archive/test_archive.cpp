// Store and forward to PostgreSQL (issue 19, docs/archive.md) against a real PostgreSQL 15 server:
// what the archive holds equals the SQLite file, a second push adds nothing, and a push cut off by
// the server stopping is finished by the next one with every sample exactly once.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "archive/background.hpp"
#include "archive/forwarder.hpp"
#include "archive/pg.hpp"
#include "archive/pg_schema.hpp"
#include "archive/pull.hpp"
#include "store/database_export.hpp"
#include "store/database.hpp"
#include "base/user_error.hpp"
#include "tests/archive/archive_checks.hpp"
#include "tests/archive/pg_server.hpp"

namespace {

using manikind::ExitStatus;
using manikind::UserError;
using manikind::archive::PgConnection;
using manikind::archive::push;
using manikind::archive::PushOptions;
using manikind::recorder::Database;
using manikind::recorder::SampleRow;
using manikind::test::PgServer;

class TempDir {
public:
    TempDir() {
        char pattern[] = "/tmp/manikind-archive-test-XXXXXX";
        if (!mkdtemp(pattern)) throw std::runtime_error("mkdtemp failed");
        path_ = pattern;
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    ~TempDir() {
        std::error_code ec;
        std::filesystem::remove_all(path_, ec);
    }
    const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
};

using manikind::test::check_archive_equals_sqlite;

std::int64_t archive_count(const std::string& conninfo, const std::string& sql) {
    auto pg = PgConnection::connect(conninfo);
    return pg.exec(sql).int64(0, 0);
}

using manikind::test::run_manikin;

std::string read_file(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

constexpr std::int64_t second_ns = 1'000'000'000;

// Three channels (one with a backslash, to exercise COPY's escaping) sampled every second from
// `from_step`; every 97th value is NaN (stored as NULL).
void add_samples(Database& db, std::int64_t trial, const std::vector<std::int64_t>& channels, int from_step,
                 int steps) {
    std::vector<SampleRow> rows;
    for (int step = from_step; step < from_step + steps; ++step) {
        for (std::size_t c = 0; c < channels.size(); ++c) {
            SampleRow row;
            row.trial_id = trial;
            row.channel_id = channels[c];
            row.mono_ns = 5'000 * second_ns + step * second_ns;
            row.utc_ns = 1'790'000'000 * second_ns + step * second_ns;
            row.value = step % 97 == 0 ? std::numeric_limits<double>::quiet_NaN()
                                       : 20.0 + 0.001 * step + 1.5 * static_cast<double>(c) + 1e-7 * static_cast<double>(trial);
            row.quality = static_cast<std::uint8_t>(step % 4 == 0 ? 1 : 0);
            rows.push_back(row);
        }
    }
    db.insert_samples(rows);
}

struct LabDb {
    std::int64_t done_trial = 0;
    std::int64_t running_trial = 0;
    std::vector<std::int64_t> channels;
};

// Two trials of one case: the first done with 1500 time steps, the second still acquiring with 1200.
LabDb build_lab_db(const std::filesystem::path& path) {
    auto db = Database::open(path);
    LabDb lab;
    const auto campaign = db.create_campaign("archive-test", R"({"name": "archive-test", "replicates": 2})");
    const auto case_id = db.add_case(campaign, "case 1", R"({"id": 1, "air_temp_c": 30, "rh_pct": 40})", 0);
    lab.done_trial = db.create_trial(campaign, case_id, 1);
    lab.running_trial = db.create_trial(campaign, case_id, 2);
    const auto chamber = db.device_id("chamber", "modbus", "127.0.0.1:502");
    const auto manikin = db.device_id("manikin", "can", "socketpair");
    lab.channels = {db.channel_id(chamber, "air_temp_pv_c", "degC"), db.channel_id(chamber, "air_rh_pv_pct", "%"),
                    db.channel_id(manikin, "zone\\1 skin_c", "degC")};
    db.set_trial_state(lab.done_trial, "acquiring", "", 1'790'000'000 * second_ns);
    add_samples(db, lab.done_trial, lab.channels, 0, 1500);
    db.set_trial_state(lab.done_trial, "done", "steady", 1'790'002'000 * second_ns);
    db.set_trial_state(lab.running_trial, "acquiring", "", 1'790'003'000 * second_ns);
    add_samples(db, lab.running_trial, lab.channels, 0, 1200);
    db.add_event(lab.done_trial, 5'000 * second_ns, 1'790'000'000 * second_ns, "info", "stage", "acquiring");
    db.add_event(std::nullopt, 5'001 * second_ns, 1'790'000'001 * second_ns, "warn", "device",
                 "windsonic: silent\tfor 3 s\nback");
    return lab;
}

// A test's own server and a lab database with two trials (build_lab_db) in a fresh folder.
struct LabAndServer {
    PgServer server;
    TempDir tmp;
    std::filesystem::path db_path = tmp.path() / "lab.db";
    LabDb lab = build_lab_db(db_path);
};

// run_if_postgres.sh skips under CTest; run by hand, a test says it skipped.
#define SKIP_WITHOUT_POSTGRES()                                                          \
    do {                                                                                 \
        if (!PgServer::available()) {                                                    \
            WARN("skipped: no PostgreSQL 15 server binaries in " << PgServer::bin_dir); \
            return;                                                                      \
        }                                                                                \
    } while (false)

// The same bits, NaN included (== would call two NaNs different and -0.0 equal to 0.0).
bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

// What campaign_from_database made of the lab's file and of the pulled copy: equal in every
// number. provenance "database" names the file it read, so it differs by design.
void check_same_campaign(const manikind::analysis::Campaign& want, const manikind::analysis::Campaign& got) {
    CHECK(got.name == want.name);
    REQUIRE(got.channels.size() == want.channels.size());
    for (std::size_t k = 0; k < want.channels.size(); ++k) {
        CHECK(got.channels[k].column() == want.channels[k].column());
        CHECK(got.channels[k].unit == want.channels[k].unit);
    }
    auto want_provenance = want.provenance, got_provenance = got.provenance;
    want_provenance.erase("database");
    got_provenance.erase("database");
    CHECK(got_provenance == want_provenance);
    REQUIRE(got.trials.size() == want.trials.size());
    for (std::size_t t = 0; t < want.trials.size(); ++t) {
        const auto &w = want.trials[t], &g = got.trials[t];
        INFO("trial " << w.info.id);
        CHECK(g.info.id == w.info.id);
        CHECK(g.info.case_id == w.info.case_id);
        CHECK(g.info.replicate == w.info.replicate);
        CHECK(g.info.started_utc == w.info.started_utc);
        CHECK(g.info.t0_utc_ns == w.info.t0_utc_ns);
        CHECK(g.info.skin_setpoint_c == w.info.skin_setpoint_c);
        CHECK(g.info.wettedness == w.info.wettedness);
        CHECK(g.info.chamber_setpoint_temp_c == w.info.chamber_setpoint_temp_c);
        CHECK(g.info.chamber_setpoint_rh_pct == w.info.chamber_setpoint_rh_pct);
        CHECK(same_bits(g.data.t_s, w.data.t_s));
        CHECK(g.data.utc_ns == w.data.utc_ns);
        CHECK(same_bits(g.data.air_temp_c, w.data.air_temp_c));
        CHECK(same_bits(g.data.air_rh_pct, w.data.air_rh_pct));
        CHECK(same_bits(g.data.air_speed_m_s, w.data.air_speed_m_s));
        CHECK(same_bits(g.data.wall_temp_c, w.data.wall_temp_c));
        REQUIRE(g.data.skin_temp_c.size() == w.data.skin_temp_c.size());
        for (std::size_t z = 0; z < w.data.skin_temp_c.size(); ++z) {
            CHECK(same_bits(g.data.skin_temp_c[z], w.data.skin_temp_c[z]));
            CHECK(same_bits(g.data.heat_flux_w_m2[z], w.data.heat_flux_w_m2[z]));
        }
        REQUIRE(g.data.channel_values.size() == w.data.channel_values.size());
        for (std::size_t k = 0; k < w.data.channel_values.size(); ++k) {
            INFO("channel " << want.channels[k].column());
            CHECK(same_bits(g.data.channel_values[k], w.data.channel_values[k]));
            CHECK(g.data.channel_quality[k] == w.data.channel_quality[k]);
        }
    }
}

}  // namespace

TEST_CASE("archive push sends everything once and a second push adds nothing", "[archive]") {
    SKIP_WITHOUT_POSTGRES();
    LabAndServer f;
    auto& server = f.server;
    const auto& db_path = f.db_path;
    const auto& lab = f.lab;

    auto first = push(db_path, server.conninfo(), "lab-3");
    CHECK(first.archive_schema_version == manikind::archive::pg_latest_schema_version());
    CHECK(first.campaigns.sent == 1);
    CHECK(first.campaigns.added == 1);
    CHECK(first.trials.added == 2);
    CHECK(first.channels.added == 3);
    CHECK(first.events.sent == 2);
    CHECK(first.events.added == 2);
    CHECK(first.samples.sent == (1500 + 1200) * 3);
    CHECK(first.samples.added == (1500 + 1200) * 3);
    CHECK(first.trials_complete == 1);
    CHECK(first.trials_partial == 1);
    check_archive_equals_sqlite(db_path, server.conninfo());
    // NaN travels as NULL: steps 0, 97, ... of each trial, on each of the 3 channels.
    CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM samples WHERE value IS NULL") ==
          3 * ((1 + 1499 / 97) + (1 + 1199 / 97)));
    CHECK(archive_count(server.conninfo(),
                        "SELECT count(*) FROM events WHERE message = E'windsonic: silent\\tfor 3 s\\nback'") == 1);

    SECTION("a second push sends no samples and adds nothing") {
        auto again = push(db_path, server.conninfo(), "lab-3");
        CHECK(again.campaigns.added == 0);
        CHECK(again.trials.added == 0);
        CHECK(again.channels.added == 0);
        CHECK(again.events.added == 0);
        CHECK(again.samples.sent == 0);
        CHECK(again.samples.added == 0);
        check_archive_equals_sqlite(db_path, server.conninfo());
    }

    SECTION("once the running trial ends, the next push completes it without doubling a row") {
        {
            auto db = Database::open(db_path);
            add_samples(db, lab.running_trial, lab.channels, 1200, 300);
            db.set_trial_state(lab.running_trial, "done", "steady", 1'790'005'000 * second_ns);
        }
        auto after = push(db_path, server.conninfo(), "lab-3");
        CHECK(after.trials.added == 1);  // its state changed
        CHECK(after.samples.sent == 1500 * 3);  // the terminal pass reads it again from the start
        CHECK(after.samples.added == 300 * 3);
        CHECK(after.trials_complete == 2);
        CHECK(after.trials_partial == 0);
        check_archive_equals_sqlite(db_path, server.conninfo());
        auto last = push(db_path, server.conninfo(), "lab-3");
        CHECK(last.samples.sent == 0);
        CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM forward_progress WHERE complete") == 2);
    }

    SECTION("the CLI: counts as JSON, exit 0; the server gone, exit 3 with archive_unreachable") {
        auto r = run_manikin("archive push " + db_path.string() + " --to '" + server.conninfo() + "' --lab lab-3 --json");
        CHECK(r.status == 0);
        const auto doc = nlohmann::json::parse(r.out);
        CHECK(doc["samples"]["sent"] == 0);
        CHECK(doc["trials_complete"] == 1);
        CHECK(doc["lab"] == "lab-3");
        server.stop();
        r = run_manikin("archive push " + db_path.string() + " --to '" + server.conninfo() + "' --lab lab-3 --json");
        CHECK(r.status == 3);
        CHECK(nlohmann::json::parse(r.out)["error"]["code"] == "archive_unreachable");
        server.start();
    }

    SECTION("progress rows lost while their samples stayed: the plain COPY meets a key already there, the chunk goes "
            "again with ON CONFLICT, and every row is still there once") {
        {
            auto pg = PgConnection::connect(server.conninfo());
            pg.exec("DELETE FROM forward_progress WHERE source_table = 'samples'");
        }
        auto again = push(db_path, server.conninfo(), "lab-3");
        CHECK(again.samples.sent == (1500 + 1200) * 3);
        CHECK(again.samples.added == 0);
        CHECK(again.chunks_resent >= 1);
        check_archive_equals_sqlite(db_path, server.conninfo());
        CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM sample_rows") == (1500 + 1200) * 3);
    }

    SECTION("samples are stored under integer keys, and the samples view gives them back with their names") {
        CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM sample_rows") == (1500 + 1200) * 3);
        CHECK(archive_count(server.conninfo(), "SELECT count(DISTINCT channel_key) FROM sample_rows") == 3);
        CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM samples WHERE channel = 'zone\\1 skin_c'") == 2700);
    }

    SECTION("the same file under another lab id is refused: its trials belong to lab-3") {
        try {
            push(db_path, server.conninfo(), "lab-4");
            FAIL("no error");
        } catch (const UserError& e) {
            CHECK(e.status() == ExitStatus::refused);
            CHECK_THAT(e.what(), Catch::Contains("belongs to lab 'lab-3'"));
        }
    }
}

TEST_CASE("archive push cut off by the server stopping resumes with every sample exactly once", "[archive]") {
    SKIP_WITHOUT_POSTGRES();
    LabAndServer f;
    auto& server = f.server;
    const auto& db_path = f.db_path;
    const auto& lab = f.lab;
    {
        auto db = Database::open(db_path);
        db.set_trial_state(lab.running_trial, "done", "steady", 1'790'005'000 * second_ns);
    }
    const std::int64_t total = (1500 + 1200) * 3;

    SECTION("bad input and an unreachable server are told apart") {
        try {
            push(db_path, server.conninfo(), "lab 3");
            FAIL("no error");
        } catch (const UserError& e) {
            CHECK(e.status() == ExitStatus::bad_input);
        }
        try {
            push(f.tmp.path() / "none.db", server.conninfo(), "lab-3");
            FAIL("no error");
        } catch (const UserError& e) {
            CHECK(e.status() == ExitStatus::bad_input);
            CHECK_THAT(e.what(), Catch::Contains("none.db"));
        }
        try {
            push(db_path, "host=" + f.tmp.path().string() + " port=1 dbname=postgres", "lab-3");
            FAIL("no error");
        } catch (const UserError& e) {
            CHECK(e.status() == ExitStatus::unreachable);
            CHECK(e.code() == "archive_unreachable");
        }
    }

    SECTION("stopped after the first chunk: a clear error, then the next push sends the rest") {
        PushOptions options;
        options.chunk_rows = 1000;
        int chunks_seen = 0;
        options.after_chunk = [&](const manikind::archive::ChunkCommitted& chunk) {
            ++chunks_seen;
            CHECK(chunk.rows == 1000);
            server.stop();
        };
        try {
            push(db_path, server.conninfo(), "lab-3", options);
            FAIL("the push went on with the server stopped");
        } catch (const UserError& e) {
            CHECK(e.status() == ExitStatus::unreachable);
            CHECK(e.code() == "archive_unreachable");
            CHECK_THAT(e.what(), Catch::Contains("archive"));
        }
        CHECK(chunks_seen == 1);

        server.start();
        CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM samples") == 1000);
        options.after_chunk = nullptr;
        auto resumed = push(db_path, server.conninfo(), "lab-3", options);
        CHECK(resumed.samples.sent == total - 1000);  // resumed after the committed chunk, not from the start
        CHECK(resumed.samples.added == total - 1000);
        CHECK(resumed.trials_complete == 2);
        check_archive_equals_sqlite(db_path, server.conninfo());
        CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM samples") == total);

        auto again = push(db_path, server.conninfo(), "lab-3", options);
        CHECK(again.samples.sent == 0);
        CHECK(again.samples.added == 0);
    }
}

TEST_CASE("archive pull gives analyze the same campaign as the lab database", "[archive]") {
    SKIP_WITHOUT_POSTGRES();
    PgServer server;
    TempDir tmp;

    SECTION("a hand-made database: NaN, flagged samples and a backslash in a name come back bit for bit") {
        const auto db_path = tmp.path() / "lab.db";
        const auto lab = build_lab_db(db_path);
        {
            // campaign_from_database reads done trials between their "acquiring" and "stopping" stages.
            auto db = Database::open(db_path);
            db.add_event(lab.done_trial, 6'499 * second_ns, 1'790'001'499 * second_ns, "info", "stage", "stopping");
            db.add_event(lab.running_trial, 5'000 * second_ns, 1'790'003'000 * second_ns, "info", "stage", "acquiring");
            add_samples(db, lab.running_trial, lab.channels, 1200, 300);
            db.add_event(lab.running_trial, 6'499 * second_ns, 1'790'004'499 * second_ns, "info", "stage", "stopping");
            db.set_trial_state(lab.running_trial, "done", "steady", 1'790'005'000 * second_ns);
            // The lab notebook: one note on the campaign, one on a trial (newline and quote inside).
            const auto campaign = db.find_campaign("archive-test").value();
            db.add_note({0, campaign, std::nullopt, 1'790'000'010 * second_ns, "ana", "operator", "Ana ran it"});
            db.add_note({0, campaign, lab.done_trial, 1'790'000'020 * second_ns, "bo", "garment", "sleeve \"torn\",\n\tzone 12"});
        }
        const auto pushed = push(db_path, server.conninfo(), "lab-3");
        CHECK(pushed.notes.sent == 2);
        CHECK(pushed.notes.added == 2);
        CHECK(push(db_path, server.conninfo(), "lab-3").notes.added == 0);  // never twice

        auto original = Database::open(db_path);
        const auto want = manikind::campaign_from_database(original, "archive-test");
        auto pulled_db = Database::open(tmp.path() / "pulled.db");
        const auto pulled = manikind::archive::pull_campaign(server.conninfo(), "lab-3", "archive-test", pulled_db);
        CHECK(pulled.trials == 2);
        CHECK(pulled.samples == 1500 * 3 * 2);
        const auto got = manikind::campaign_from_database(pulled_db, "archive-test");
        REQUIRE(want.trials.size() == 2);
        check_same_campaign(want, got);
        CHECK(pulled.notes == 2);
        REQUIRE(got.notes.size() == 2);
        REQUIRE(want.notes.size() == 2);
        for (std::size_t i = 0; i < 2; ++i) {
            CHECK(got.notes[i].utc_ns == want.notes[i].utc_ns);
            CHECK(got.notes[i].author == want.notes[i].author);
            CHECK(got.notes[i].kind == want.notes[i].kind);
            CHECK(got.notes[i].text == want.notes[i].text);
            CHECK(got.notes[i].trial == want.notes[i].trial);
        }
        CHECK(got.notes[1].text == "sleeve \"torn\",\n\tzone 12");
        CHECK_FALSE(got.notes[1].trial.empty());
        // The UUIDs, states and times travel as they were.
        const auto want_trials = original.trials(original.find_campaign("archive-test").value());
        const auto got_trials = pulled_db.trials(pulled_db.find_campaign("archive-test").value());
        REQUIRE(got_trials.size() == want_trials.size());
        for (std::size_t i = 0; i < want_trials.size(); ++i) {
            CHECK(got_trials[i].uuid == want_trials[i].uuid);
            CHECK(got_trials[i].state == want_trials[i].state);
            CHECK(got_trials[i].reason == want_trials[i].reason);
            CHECK(got_trials[i].replicate == want_trials[i].replicate);
            CHECK(got_trials[i].started_utc_ns == want_trials[i].started_utc_ns);
            CHECK(got_trials[i].ended_utc_ns == want_trials[i].ended_utc_ns);
        }

        // Unknown names are input errors that say what there is.
        try {
            Database scratch = Database::open(tmp.path() / "scratch.db");
            manikind::archive::pull_campaign(server.conninfo(), "lab-3", "no-such-campaign", scratch);
            FAIL("no error");
        } catch (const UserError& e) {
            CHECK(e.status() == ExitStatus::bad_input);
            CHECK_THAT(e.what(), Catch::Contains("archive-test"));
        }
        try {
            Database scratch = Database::open(tmp.path() / "scratch2.db");
            manikind::archive::pull_campaign(server.conninfo(), "lab-9", "archive-test", scratch);
            FAIL("no error");
        } catch (const UserError& e) {
            CHECK(e.status() == ExitStatus::bad_input);
            CHECK_THAT(e.what(), Catch::Contains("lab-9"));
        }
    }

    SECTION("a simulated campaign: manikin analyze --archive prints what analyze --db prints") {
        const auto demo = tmp.path() / "demo";
        const auto made = run_manikin("demo --cases 2 --replicates 2 --json --out " + demo.string() + " >/dev/null 2>&1");
        REQUIRE(made.status == 0);
        const std::string db = (demo / "manikind.db").string();
        const auto campaigns = nlohmann::json::parse(run_manikin("campaigns --json --db " + db).out);
        REQUIRE(campaigns.size() == 1);
        const std::string name = campaigns[0]["name"];
        push(db, server.conninfo(), "lab-7");

        {
            auto original = Database::open(db);
            auto pulled_db = Database::open(tmp.path() / "demo-pulled.db");
            manikind::archive::pull_campaign(server.conninfo(), "lab-7", name, pulled_db);
            check_same_campaign(manikind::campaign_from_database(original, name),
                                manikind::campaign_from_database(pulled_db, name));
        }

        const auto from_db = run_manikin("analyze --db " + db + " --campaign " + name + " --json");
        const auto from_archive =
            run_manikin("analyze --archive '" + server.conninfo() + "' --lab lab-7 --campaign " + name + " --json");
        REQUIRE(from_db.status == 0);
        REQUIRE(from_archive.status == 0);
        CHECK(nlohmann::json::parse(from_db.out)["cases"].size() == 2);
        CHECK(from_archive.out == from_db.out);

        // manikin export --archive reads the pulled file a trial at a time, as from the lab's own:
        // the same trials, byte for byte, and the archive named as the source.
        const auto csv_db = tmp.path() / "export-db", csv_archive = tmp.path() / "export-archive";
        REQUIRE(run_manikin("export --db " + db + " " + name + " " + csv_db.string() + " >/dev/null").status == 0);
        REQUIRE(run_manikin("export --archive '" + server.conninfo() + "' --lab lab-7 " + name + " " + csv_archive.string() +
                            " >/dev/null")
                    .status == 0);
        std::size_t compared = 0;
        for (const auto& f : std::filesystem::directory_iterator(csv_db / "trials")) {
            const auto other = csv_archive / "trials" / f.path().filename();
            REQUIRE(std::filesystem::exists(other));
            CHECK(read_file(f.path()) == read_file(other));
            ++compared;
        }
        CHECK(compared == 4);
        const auto meta = nlohmann::json::parse(read_file(csv_archive / "campaign.json"));
        CHECK_THAT(meta["provenance"]["database"].get<std::string>(), Catch::Contains("lab lab-7"));
        REQUIRE(run_manikin("export --archive '" + server.conninfo() + "' --lab lab-7 " + name + " " +
                            (tmp.path() / "a.h5").string() + " --format hdf5 >/dev/null")
                    .status == 0);

        // The temporary database is gone afterwards.
        const auto unknown =
            run_manikin("analyze --archive '" + server.conninfo() + "' --lab lab-7 --campaign nope --json");
        CHECK(unknown.status == 2);
        CHECK_THAT(unknown.out, Catch::Contains(name));
        server.stop();
        const auto gone =
            run_manikin("analyze --archive '" + server.conninfo() + "' --lab lab-7 --campaign " + name + " --json");
        CHECK(gone.status == 3);
        server.start();
    }
}

namespace {

// The idle log: `steps` readings of every channel 10 s apart from `from_step` (wall clock only:
// the idle log is keyed by utc_ns).
void add_idle_samples(Database& db, const std::vector<std::int64_t>& channels, int from_step, int steps) {
    std::vector<SampleRow> rows;
    for (int step = from_step; step < from_step + steps; ++step) {
        for (std::size_t c = 0; c < channels.size(); ++c) {
            SampleRow row;
            row.trial_id = 0;
            row.channel_id = channels[c];
            row.mono_ns = 100 * second_ns + step * 10 * second_ns;
            row.utc_ns = 1'789'000'000 * second_ns + step * 10 * second_ns;
            row.value = 18.0 + 0.01 * step + static_cast<double>(c);
            row.quality = 0;
            rows.push_back(row);
        }
    }
    db.insert_samples(rows);
}

}  // namespace

TEST_CASE("archive push sends the idle log and lab metadata once and trial_steps has a row per time step",
          "[archive]") {
    SKIP_WITHOUT_POSTGRES();
    LabAndServer f;
    auto& server = f.server;
    const auto& db_path = f.db_path;
    const auto& lab = f.lab;
    std::string done_uuid;
    double idle_sum = 0.0;  // of the values add_idle_samples wrote
    const auto idle_value_sum = [](int from_step, int steps) {
        double sum = 0.0;
        for (int step = from_step; step < from_step + steps; ++step)
            for (int c = 0; c < 3; ++c) sum += 18.0 + 0.01 * step + c;
        return sum;
    };
    {
        auto db = Database::open(db_path);
        const auto campaign = db.find_campaign("archive-test").value();
        db.store_result(campaign, R"({"cases": [{"case": 1, "n_replicates": 1}]})", 1'790'006'000 * second_ns);
        db.store_result(campaign, R"({"cases": [{"case": 1, "n_replicates": 2}]})", 1'790'007'000 * second_ns);
        db.store_twin_version("andi", 1, "[zones]\nn = 35\n");
        const manikind::recorder::Setup setup{"lab three", "Weiss WK3 #58226", "ANDI #12",
                          R"({"instruments":{"air_temp_c":{"accuracy":0.2}}})", "[lab]\nname = \"lab three\"\n"};
        db.set_trial_setup(lab.done_trial, db.record_setup(setup, 1'790'000'000 * second_ns));
        add_idle_samples(db, lab.channels, 0, 50);
        idle_sum += idle_value_sum(0, 50);
        done_uuid = db.trial(lab.done_trial).value().uuid;
    }
    const auto idle_count = [&] {
        return archive_count(server.conninfo(), "SELECT count(*) FROM idle_samples WHERE lab_id = 'lab-3'");
    };
    const auto archive_idle_sum = [&] {
        auto pg = PgConnection::connect(server.conninfo());
        return std::stod(pg.exec("SELECT sum(value) FROM idle_samples WHERE lab_id = 'lab-3'").text(0, 0));
    };

    auto first = push(db_path, server.conninfo(), "lab-3");
    CHECK(first.devices.sent == 2);
    CHECK(first.devices.added == 2);
    CHECK(first.results.sent == 2);
    CHECK(first.results.added == 2);
    CHECK(first.twin_versions.added == 1);
    CHECK(first.setups.added == 1);
    // The trial names its set-up, and analysts read the calibration as JSON.
    CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM trial_setups WHERE trial_uuid = '" + done_uuid +
                                               "' AND chamber = 'Weiss WK3 #58226' AND manikin = 'ANDI #12'"
                                               " AND (calibration->'instruments'->'air_temp_c'->>'accuracy')::float8 = 0.2"
                                               " AND length(setup_sha256) = 64") == 1);
    CHECK(first.idle_samples.sent == 50 * 3);
    CHECK(first.idle_samples.added == 50 * 3);
    CHECK_FALSE(first.idle_resent);
    CHECK(idle_count() == 50 * 3);
    CHECK(archive_idle_sum() == Approx(idle_sum).epsilon(1e-12));
    CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM devices WHERE lab_id = 'lab-3' AND device = 'chamber'"
                                           " AND kind = 'modbus' AND transport = '127.0.0.1:502'") == 1);
    CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM results WHERE campaign_name = 'archive-test'"
                                           " AND json LIKE '%\"n_replicates\": 2%'") == 1);
    CHECK(archive_count(server.conninfo(), "SELECT count(*) FROM twin_versions WHERE twin_name = 'andi' AND version = 1"
                                           " AND toml = E'[zones]\\nn = 35\\n'") == 1);

    // A second push adds nothing; only the idle log's last minute (6 steps of 10 s) is read
    // again, in case a late row lands there.
    auto again = push(db_path, server.conninfo(), "lab-3");
    CHECK(again.devices.added == 0);
    CHECK(again.results.added == 0);
    CHECK(again.twin_versions.added == 0);
    CHECK(again.setups.added == 0);
    CHECK(again.setups.sent == 1);
    CHECK(again.trials.added == 0);
    CHECK(again.samples.added == 0);
    CHECK(again.events.added == 0);
    CHECK(again.idle_samples.added == 0);
    CHECK(again.idle_samples.sent == 6 * 3);
    CHECK_FALSE(again.idle_resent);

    // New idle readings: only they arrive.
    {
        auto db = Database::open(db_path);
        add_idle_samples(db, lab.channels, 50, 20);
        idle_sum += idle_value_sum(50, 20);
    }
    auto more = push(db_path, server.conninfo(), "lab-3");
    CHECK(more.idle_samples.added == 20 * 3);
    CHECK(more.idle_samples.sent == (6 + 20) * 3);
    CHECK_FALSE(more.idle_resent);
    CHECK(idle_count() == 70 * 3);

    // The wall clock stepped back an hour: rows behind the progress are noticed and sent.
    {
        auto db = Database::open(db_path);
        add_idle_samples(db, lab.channels, -400, 10);
        idle_sum += idle_value_sum(-400, 10);
    }
    auto stepped = push(db_path, server.conninfo(), "lab-3");
    CHECK(stepped.idle_resent);
    CHECK(stepped.idle_samples.added == 10 * 3);
    CHECK(idle_count() == 80 * 3);
    CHECK(archive_idle_sum() == Approx(idle_sum).epsilon(1e-12));
    auto settled = push(db_path, server.conninfo(), "lab-3");
    CHECK_FALSE(settled.idle_resent);
    CHECK(settled.idle_samples.added == 0);

    // trial_steps: one row per time step of the trial, values by "device.channel".
    auto db = Database::open(db_path);
    std::set<std::int64_t> mono_ns;
    db.for_each_trial_sample(lab.done_trial, [&](const SampleRow& row) { mono_ns.insert(row.mono_ns); });
    auto pg = PgConnection::connect(server.conninfo());
    CHECK(pg.exec("SELECT count(*) FROM trial_steps WHERE trial_uuid = $1", {done_uuid}).int64(0, 0) ==
          static_cast<std::int64_t>(mono_ns.size()));
    const auto want = db.samples(lab.done_trial, lab.channels[0]).at(1);
    auto step = pg.exec("SELECT channel_values ->> 'chamber.air_temp_pv_c', utc_ns, n_channels FROM trial_steps"
                        " WHERE trial_uuid = $1 AND mono_ns = $2",
                        {done_uuid, std::to_string(want.mono_ns)});
    REQUIRE(step.rows() == 1);
    CHECK(std::stod(step.text(0, 0)) == want.value);
    CHECK(step.int64(0, 1) == want.utc_ns);
    CHECK(step.int64(0, 2) == 3);
}

TEST_CASE("the daemon's forwarder counts the idle log for stepped-back rows at its first pass and then once per "
          "idle_check_interval and not at every pass",
          "[archive]") {
    SKIP_WITHOUT_POSTGRES();
    LabAndServer f;
    const auto idle_count = [&] {
        return archive_count(f.server.conninfo(), "SELECT count(*) FROM idle_samples WHERE lab_id = 'lab-3'");
    };
    const auto add_idle = [&](int from_step, int steps) {
        auto db = Database::open(f.db_path);
        add_idle_samples(db, f.lab.channels, from_step, steps);
    };
    add_idle(0, 50);
    manikind::archive::ForwardingOptions fo;
    fo.database = f.db_path;
    fo.conninfo = f.server.conninfo();
    fo.lab_id = "lab-3";
    fo.interval = std::chrono::hours(1);  // no pass of its own after the first: only the ones asked for
    const auto quiet = [](const std::string&, const std::string&) {};
    {
        fo.idle_check_interval = std::chrono::hours(1);  // the daemon's default
        manikind::archive::BackgroundForwarder forwarder(fo, quiet);
        REQUIRE(forwarder.forward_now());
        CHECK(idle_count() == 50 * 3);
        // Rows far behind the progress (a clock stepped back 66 min): a pass within the hour does
        // not count the log, so it does not see them; it still sends new rows at the end.
        add_idle(-400, 10);
        add_idle(50, 5);
        REQUIRE(forwarder.forward_now());
        CHECK(idle_count() == 55 * 3);
    }
    {
        fo.idle_check_interval = std::chrono::milliseconds(0);  // every pass is "an hour later"
        manikind::archive::BackgroundForwarder forwarder(fo, quiet);
        REQUIRE(forwarder.forward_now());
        CHECK(idle_count() == 65 * 3);  // the stepped-back rows, found by the first pass's count
        add_idle(-800, 10);
        REQUIRE(forwarder.forward_now());
        CHECK(idle_count() == 75 * 3);  // and by a later pass's, once the interval has passed
    }
}

TEST_CASE("archive schema v5: an archive of version 4 with samples keeps every one under the integer keys", "[archive]") {
    SKIP_WITHOUT_POSTGRES();
    LabAndServer f;
    // Version 4 as a push of the previous program left it (its four migrations, then another lab's rows).
    {
        auto pg = PgConnection::connect(f.server.conninfo());
        pg.exec("CREATE TABLE schema_version (version integer NOT NULL)");
        const auto migrations = manikind::archive::pg_migrations();
        for (std::size_t v = 0; v < 4; ++v) pg.exec_script(migrations[v]);
        pg.exec("INSERT INTO schema_version VALUES (4)");
        pg.exec("INSERT INTO labs VALUES ('lab-0', 'lab-0', 1)");
        pg.exec("INSERT INTO campaigns VALUES ('lab-0', 'c', '{}', 1, 'done')");
        pg.exec("INSERT INTO trials (trial_uuid, lab_id, campaign_name, case_name, replicate, state, reason, conditions_json)"
                " VALUES ('0123456789abcdef0123456789abcdef', 'lab-0', 'c', 'case 1', 1, 'done', '', '{}')");
        pg.exec("INSERT INTO channels VALUES ('lab-0', 'manikin', 'z01.skin_temp_c', 'degC'), ('lab-0', 'chamber', 'pv', 'degC')");
        pg.exec("INSERT INTO samples SELECT '0123456789abcdef0123456789abcdef', d, ch, g, g + 7, g * 0.5, 0"
                " FROM generate_series(1, 500) g, (VALUES ('manikin', 'z01.skin_temp_c'), ('chamber', 'pv')) AS x(d, ch)");
    }
    // The next push migrates it, then sends its own file beside.
    auto r = push(f.db_path, f.server.conninfo(), "lab-3");
    CHECK(r.archive_schema_version == 5);
    CHECK(archive_count(f.server.conninfo(), "SELECT count(*) FROM samples WHERE trial_uuid = '0123456789abcdef0123456789abcdef'") == 1000);
    CHECK(archive_count(f.server.conninfo(), "SELECT sum(mono_ns) FROM samples WHERE trial_uuid = '0123456789abcdef0123456789abcdef'"
                                             " AND device = 'chamber'") == 500 * 501 / 2);
    CHECK(archive_count(f.server.conninfo(), "SELECT count(*) FROM trial_steps WHERE trial_uuid = '0123456789abcdef0123456789abcdef'") == 500);
    check_archive_equals_sqlite(f.db_path, f.server.conninfo(), "lab-3");
}
