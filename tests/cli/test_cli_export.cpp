// Data out (issue 16): a campaign recorded by the daemon on the simulated lab, exported to CSV
// (manikin-recording/2) and HDF5, read back; every recorded channel equals the database's
// samples, with UTC, units, quality and provenance. The SQLite views give the same table.
#include <catch2/catch.hpp>

#include <sqlite3.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>
#include <filesystem>
#include <map>
#include <memory>

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "analysis/recording.hpp"
#include "store/hdf5_export.hpp"
#include "store/database.hpp"
#include "run_cli.hpp"

namespace fs = std::filesystem;
namespace an = manikind::analysis;
using manikind::test::run_manikin;

namespace {

struct TempDir {
    fs::path path = fs::temp_directory_path() / ("manikind-export-" + std::to_string(::getpid()));
    TempDir() { fs::remove_all(path); }
    ~TempDir() { fs::remove_all(path); }
};

// One campaign recorded once for every test in this file (the demo: daemon, devices over their
// transports, virtual clock).
const fs::path& recorded_database() {
    static TempDir dir;
    static const fs::path db = [] {
        const auto r = run_manikin("demo --cases 2 --replicates 1 --out " + dir.path.string() + " > /dev/null");
        REQUIRE(r.exit_code == 0);
        return dir.path / "manikind.db";
    }();
    return db;
}

std::string only_campaign(manikind::recorder::Database& db) {
    const auto campaigns = db.campaigns();
    REQUIRE(campaigns.size() == 1);
    return campaigns.front().name;
}

}  // namespace

TEST_CASE("export: CSV and HDF5 carry every recorded channel exactly as the database holds it", "[cli][export][proof]") {
    const fs::path db_path = recorded_database();
    auto db = manikind::recorder::Database::open(db_path);
    const std::string campaign = only_campaign(db);
    const fs::path out = db_path.parent_path() / "export-test";
    fs::remove_all(out);

    auto csv_run = run_manikin("export --db " + db_path.string() + " " + campaign + " " + (out / "csv").string() + " --json");
    REQUIRE(csv_run.exit_code == 0);
    const auto csv_doc = nlohmann::json::parse(csv_run.out);
    CHECK(csv_doc.at("format") == "manikin-recording/2");
    auto h5_run = run_manikin("export --db " + db_path.string() + " " + campaign + " " + (out / "c.h5").string() +
                              " --format hdf5 --json");
    REQUIRE(h5_run.exit_code == 0);
    CHECK(nlohmann::json::parse(h5_run.out).at("format") == "manikin-hdf5/1");
    const fs::path h5 = out / "c.h5";

    const an::Campaign back = an::read_campaign(out / "csv");
    REQUIRE(back.trials.size() == 2);
    // Every channel the daemon recorded: probes one by one, CSAT3B components, wall
    // thermocouples, heater power and sweat rate per zone.
    std::map<std::string, std::int64_t> channel_id;
    for (const auto& ch : db.channels()) channel_id[ch.device_name + "." + ch.name] = ch.id;
    REQUIRE(back.channels.size() == channel_id.size());
    for (const char* needed : {"datalogger.ee181_2.air_rh_pct", "csat3b.uz_m_s", "csat3b.sonic_temp_c",
                               "datalogger.wall_tc_4.wall_temp_c", "manikin.z35.heater_power_w_m2",
                               "manikin.z01.sweat_rate_g_m2_h"})
        CHECK(channel_id.count(needed) == 1);
    CHECK(back.provenance.at("program").starts_with("manikind "));
    CHECK(back.provenance.at("config_sha256").size() == 64);
    CHECK(manikind::hdf5_read_string_attribute(h5, "/", "config_sha256") == back.provenance.at("config_sha256"));
    CHECK(manikind::hdf5_read_string_attribute(h5, "/", "format") == "manikin-hdf5/1");

    std::size_t compared = 0;
    const auto trials = db.trials(db.find_campaign(campaign).value());
    for (const auto& trial : back.trials) {
        // The trial's database row and time base: its "acquiring" event at the exported t0.
        std::int64_t t0_mono = -1, t0_utc = -1;
        const std::int64_t trial_id = [&] {
            for (const auto& t : trials)
                for (const auto& e : db.events(t.id))
                    if (e.kind == "stage" && e.message == "acquiring" && trial.info.t0_utc_ns &&
                        *trial.info.t0_utc_ns / 1000000 == e.utc_ns / 1000000) {
                        t0_mono = e.mono_ns;
                        t0_utc = e.utc_ns;
                        return t.id;
                    }
            return std::int64_t{-1};
        }();
        REQUIRE(trial_id > 0);
        const auto& d = trial.data;
        REQUIRE(d.utc_ns.size() == d.rows());
        CHECK(d.utc_ns[0] == t0_utc / 1000000 * 1000000);  // millisecond resolution
        const std::string group = "/trials/" + trial.info.id + "/";
        CHECK(manikind::hdf5_read_doubles(h5, group + "t_s") == d.t_s);
        CHECK(manikind::hdf5_read_int64(h5, group + "utc_ns").front() == t0_utc);
        for (std::size_t k = 0; k < back.channels.size(); ++k) {
            const auto& ch = back.channels[k];
            const auto h5_values = manikind::hdf5_read_doubles(h5, group + ch.column());
            const auto h5_quality = manikind::hdf5_read_uint8(h5, group + ch.column() + ".q");
            REQUIRE(h5_values.size() == d.rows());
            for (const auto& s : db.samples(trial_id, channel_id.at(ch.column()))) {
                const std::int64_t since = s.mono_ns - t0_mono;
                if (since < 0 || since % 5000000000 != 0) continue;  // on the grid: one sample per row here
                const auto r = static_cast<std::size_t>(since / 5000000000);
                if (r >= d.rows()) continue;
                INFO(ch.column() << " row " << r);
                CHECK(d.channel_values[k][r] == s.value);  // exact: shortest round-trip text
                CHECK(h5_values[r] == s.value);
                CHECK(d.channel_quality[k][r] == s.quality);
                CHECK(h5_quality[r] == s.quality);
                ++compared;
            }
        }
    }
    // 157 channels x ~900 rows x 2 trials: a test that compared nothing cannot pass.
    CHECK(compared > 200000);
}

TEST_CASE("export: the HDF5 file holds the analysis beside the data, as analyze --json gives it", "[cli][export]") {
    const fs::path db_path = recorded_database();
    auto db = manikind::recorder::Database::open(db_path);
    const std::string campaign = only_campaign(db);
    const fs::path out = db_path.parent_path() / "export-analysis";
    fs::remove_all(out);
    REQUIRE(run_manikin("export --db " + db_path.string() + " " + campaign + " " + (out / "csv").string() + " > /dev/null")
                .exit_code == 0);
    REQUIRE(run_manikin("export --db " + db_path.string() + " " + campaign + " " + (out / "c.h5").string() +
                        " --format hdf5 > /dev/null")
                .exit_code == 0);
    const auto analyze = run_manikin("analyze " + (out / "csv").string() + " --json");
    REQUIRE(analyze.exit_code == 0);
    const auto expected = nlohmann::json::parse(analyze.out);
    const auto stored = nlohmann::json::parse(manikind::hdf5_read_string(out / "c.h5", "/results/analysis_json"));
    REQUIRE(stored.at("cases").size() == expected.at("cases").size());
    // Streamed into its reserved place after the file was closed: every case whole, to the value.
    CHECK(stored.at("cases") == expected.at("cases"));
    const auto q = manikind::hdf5_read_doubles(out / "c.h5", "/results/q_wb_w_m2");
    const auto u95 = manikind::hdf5_read_doubles(out / "c.h5", "/results/u95_w_m2");
    for (std::size_t c = 0; c < q.size(); ++c) {
        CHECK(q[c] == expected["cases"][c]["whole_body"]["q_w_m2"].get<double>());
        CHECK(u95[c] == expected["cases"][c]["whole_body"]["U"].get<double>());
    }
}

TEST_CASE("export: the format follows the output's name unless told: *.h5 is HDF5, a plain name a CSV folder, and csv "
          "into a *.h5 name is refused", "[cli][export]") {
    const fs::path db_path = recorded_database();
    auto db = manikind::recorder::Database::open(db_path);
    const std::string campaign = only_campaign(db);
    const fs::path out = db_path.parent_path() / "export-by-name";
    fs::remove_all(out);
    fs::create_directories(out);
    const auto h5 = run_manikin("export --db " + db_path.string() + " " + campaign + " " + (out / "c.H5").string() + " --json");
    REQUIRE(h5.exit_code == 0);
    CHECK(nlohmann::json::parse(h5.out).at("format") == "manikin-hdf5/1");
    REQUIRE(fs::is_regular_file(out / "c.H5"));
    std::ifstream f(out / "c.H5", std::ios::binary);
    char magic[8] = {};
    f.read(magic, 8);
    CHECK(std::string(magic, 8) == std::string("\x89HDF\r\n\x1a\n", 8));  // the HDF5 signature
    const auto folder = run_manikin("export --db " + db_path.string() + " " + campaign + " " + (out / "folder").string() + " --json");
    REQUIRE(folder.exit_code == 0);
    CHECK(fs::is_regular_file(out / "folder" / "campaign.json"));
    // The zone table travels inline: a reader needs no manikind to know zone 21 is the left hand.
    std::ifstream cj(out / "folder" / "campaign.json");
    const auto doc = nlohmann::json::parse(cj);
    REQUIRE(doc.at("zone_map").is_array());
    CHECK(doc.at("zone_map").size() == 35);
    CHECK(doc.at("zone_map")[20].at("name") == "hand_l");
    CHECK(doc.at("zone_map")[20].at("area_m2").get<double>() == Approx(0.0477));
    const auto slip = run_manikin("export --db " + db_path.string() + " " + campaign + " " + (out / "d.h5").string() + " --format csv --json");
    CHECK(slip.exit_code == 2);
    CHECK_THAT(slip.out, Catch::Contains("name a folder"));
    CHECK_FALSE(fs::exists(out / "d.h5"));
}

TEST_CASE("export: bad input is refused with the reason and nothing half-written", "[cli][export]") {
    const fs::path db_path = recorded_database();
    const fs::path out = db_path.parent_path() / "export-bad";
    fs::remove_all(out);
    CHECK(run_manikin("export --db " + db_path.string() + " no-such-campaign " + (out / "x.h5").string() + " --format hdf5")
              .exit_code == 2);
    CHECK_FALSE(fs::exists(out / "x.h5"));
    CHECK(run_manikin("export --db " + (out / "missing.db").string() + " c " + (out / "y").string()).exit_code == 2);
    const auto parquet = run_manikin("export --db " + db_path.string() + " c " + (out / "y").string() + " --format parquet --json");
    CHECK(parquet.exit_code == 2);  // docs/cli.md: a usage error
    CHECK(nlohmann::json::parse(parquet.out).at("error").at("code").is_string());
}

// Nothing but the export itself beside `folder`'s given names: no staging file left behind.
std::vector<std::string> leftovers(const fs::path& folder) {
    std::vector<std::string> hidden;
    for (const auto& e : fs::directory_iterator(folder))
        if (e.path().filename().string().starts_with(".")) hidden.push_back(e.path().filename().string());
    return hidden;
}

std::string file_bytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

TEST_CASE("export: an output never destroys an input, a database, a device or an unrelated folder (issue 30)",
          "[cli][export][hostile]") {
    const fs::path db_path = recorded_database();
    auto db = manikind::recorder::Database::open_read_only(db_path);
    const std::string campaign = only_campaign(db);
    const fs::path dir = db_path.parent_path() / "export-hostile";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string from = "export --db " + db_path.string() + " " + campaign + " ";
    const auto db_before = fs::file_size(db_path);

    // The database the export reads, as the HDF5 output, with and without --force.
    for (const std::string force : {"", " --force"}) {
        const auto r = run_manikin(from + db_path.string() + " --format hdf5 --json" + force);
        CHECK(r.exit_code == 2);
        CHECK(nlohmann::json::parse(r.out).at("error").at("message").get<std::string>().find("reads") != std::string::npos);
    }
    CHECK(fs::file_size(db_path) == db_before);
    CHECK(manikind::recorder::Database::open_read_only(db_path).integrity_check() == "ok");
    // Another SQLite database: never written over, --force or not.
    const fs::path other = dir / "other.db";
    fs::copy_file(db_path, other);
    const std::string other_bytes = file_bytes(other);
    CHECK(run_manikin(from + other.string() + " --format hdf5 --force").exit_code == 2);
    CHECK(file_bytes(other) == other_bytes);
    // A device: refused, and it stays a device.
    CHECK(run_manikin(from + "/dev/null --format hdf5 --force").exit_code == 2);
    CHECK(fs::is_character_file("/dev/null"));
    // A folder where a file is wanted: refused, nothing left.
    CHECK(run_manikin(from + dir.string() + " --format hdf5").exit_code == 2);
    // An existing file: only with --force, and then replaced by a whole export.
    const fs::path h5 = dir / "out.h5";
    { std::ofstream(h5) << "a client's report"; }
    CHECK(run_manikin(from + h5.string() + " --format hdf5").exit_code == 2);
    CHECK(file_bytes(h5) == "a client's report");
    CHECK(run_manikin(from + h5.string() + " --format hdf5 --force").exit_code == 0);
    CHECK(file_bytes(h5).substr(1, 3) == "HDF");
    // A CSV folder: a new one is written; an earlier export is replaced only with --force; a
    // folder holding anything else is never replaced.
    const fs::path csv = dir / "csv";
    CHECK(run_manikin(from + csv.string()).exit_code == 0);
    CHECK(run_manikin(from + csv.string()).exit_code == 2);
    CHECK(run_manikin(from + csv.string() + " --force").exit_code == 0);
    CHECK(fs::exists(csv / "campaign.json"));
    const fs::path thesis = dir / "thesis";
    fs::create_directories(thesis);
    { std::ofstream(thesis / "chapter1.tex") << "text"; }
    CHECK(run_manikin(from + thesis.string() + " --force").exit_code == 2);
    CHECK(file_bytes(thesis / "chapter1.tex") == "text");
    CHECK(fs::file_size(db_path) == db_before);
    CHECK(leftovers(dir).empty());
}

TEST_CASE("read-only commands open a database read-only and refuse a file that is not a manikind database untouched",
          "[cli][hostile]") {
    const fs::path dir = recorded_database().parent_path() / "foreign";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path empty = dir / "empty.db", foreign = dir / "foreign.db", text = dir / "notes.txt";
    { std::ofstream touch(empty); }
    { std::ofstream(text) << "not a database\n"; }
    REQUIRE(std::system(("sqlite3 " + foreign.string() + " 'CREATE TABLE samples_of_paint (colour TEXT)'").c_str()) == 0);
    const std::string foreign_bytes = file_bytes(foreign);
    for (const auto& f : {empty, foreign, text}) {
        for (const std::string& cmd : std::vector<std::string>{"campaigns --db ", "log --db ", "export c " + (dir / "out").string() + " --db ", "analyze --db "}) {
            const auto r = run_manikin(cmd + f.string() + " --json");
            CHECK(r.exit_code == 2);
            CHECK(nlohmann::json::parse(r.out).at("error").at("message").get<std::string>().find("not a") != std::string::npos);
        }
    }
    CHECK(fs::file_size(empty) == 0);
    CHECK(file_bytes(foreign) == foreign_bytes);
    CHECK_FALSE(fs::exists(foreign.string() + "-wal"));
    CHECK_FALSE(fs::exists(dir / "out"));
    // The lab's own database reads fine read-only, and stays as it was.
    const auto before = file_bytes(recorded_database());
    CHECK(run_manikin("campaigns --json --db " + recorded_database().string()).exit_code == 0);
    CHECK(file_bytes(recorded_database()) == before);
}

TEST_CASE("SQLite views: trial_table has a row per 5-s step and a column per channel, equal to the CSV export",
          "[cli][export]") {
    const fs::path db_path = recorded_database();
    auto db = manikind::recorder::Database::open(db_path);
    const std::string campaign = only_campaign(db);
    const fs::path out = db_path.parent_path() / "export-views";
    fs::remove_all(out);
    REQUIRE(run_manikin("export --db " + db_path.string() + " " + campaign + " " + out.string() + " > /dev/null").exit_code == 0);
    const an::Campaign exported = an::read_campaign(out);

    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open_v2(db_path.c_str(), &raw, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    std::unique_ptr<sqlite3, decltype(&sqlite3_close)> con(raw, sqlite3_close);
    const auto& trial = exported.trials.front();
    const auto& ch = exported.channels.front();
    const std::string sql = fmt::format(
        "SELECT t.t_s, t.\"{0}\", t.\"{0}.q\" FROM trial_table t JOIN trial_info i ON i.trial_id = t.trial_id "
        "WHERE i.case_number = {1} AND i.replicate = {2} AND t.t_s >= 0 ORDER BY t.t_s",
        ch.column(), trial.info.case_id, trial.info.replicate);
    sqlite3_stmt* q = nullptr;
    REQUIRE(sqlite3_prepare_v2(con.get(), sql.c_str(), -1, &q, nullptr) == SQLITE_OK);
    std::size_t r = 0, equal = 0;
    while (sqlite3_step(q) == SQLITE_ROW && r < trial.data.rows()) {
        CHECK(sqlite3_column_double(q, 0) == trial.data.t_s[r]);
        if (sqlite3_column_double(q, 1) == trial.data.channel_values[0][r]) ++equal;
        CHECK(sqlite3_column_int(q, 2) == trial.data.channel_quality[0][r]);
        ++r;
    }
    sqlite3_finalize(q);
    CHECK(r == trial.data.rows());
    CHECK(equal == r);

    // Per-case results as the daemon stored them.
    REQUIRE(sqlite3_prepare_v2(con.get(), "SELECT count(*), min(u95_w_m2) FROM case_results", -1, &q, nullptr) == SQLITE_OK);
    REQUIRE(sqlite3_step(q) == SQLITE_ROW);
    CHECK(sqlite3_column_int(q, 0) == 2);
    CHECK(sqlite3_column_double(q, 1) > 0.0);
    sqlite3_finalize(q);
}

TEST_CASE("report: a printable campaign and trial report with conditions, stages, verdicts, fluxes, notes and alarms",
          "[cli][report]") {
    const fs::path db_path = recorded_database();
    std::string campaign;
    {
        auto db = manikind::recorder::Database::open(db_path);
        campaign = only_campaign(db);
        // A note on the campaign and one on its first trial, as `manikin note` stores them.
        const auto id = db.find_campaign(campaign).value();
        const auto first = db.trials(id).front().id;
        db.add_note({0, id, std::nullopt, 1'790'000'000'000'000'000, "ana", "operator", "Ana ran it <script>alert(1)</script>"});
        db.add_note({0, id, first, 1'790'000'001'000'000'000, "bo", "garment", "sleeve torn"});
    }
    const fs::path out = db_path.parent_path() / "report.html";
    fs::remove(out);
    const auto r = run_manikin("report --db " + db_path.string() + " " + campaign + " " + out.string());
    REQUIRE(r.exit_code == 0);
    std::ifstream in(out);
    const std::string html((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    CHECK(html.find("<h2>Conditions and whole-body heat flux</h2>") != std::string::npos);
    CHECK(html.find("<svg") != std::string::npos);                         // the results figure
    CHECK(html.find("<section class=\"trial\"><h2>Trial c01-r1") != std::string::npos);
    CHECK(html.find("<section class=\"trial\"><h2>Trial c02-r1") != std::string::npos);
    CHECK(html.find("<td>acquiring</td>") != std::string::npos);           // the stage table
    CHECK(html.find("Steady state: steady") != std::string::npos);
    CHECK(html.find("sleeve torn") != std::string::npos);
    CHECK(html.find("<script>") == std::string::npos);                     // a note is text, never markup
    CHECK(html.find("&lt;script&gt;") != std::string::npos);
    // The case's flux and interval, as `manikin analyze --db` gives them.
    const auto a = run_manikin("analyze --db " + db_path.string() + " --campaign " + campaign + " --json");
    REQUIRE(a.exit_code == 0);
    const auto wb = nlohmann::json::parse(a.out)["cases"][0]["whole_body"];
    CHECK(html.find(fmt::format("<td>{:.2f}</td><td>{:.2f}</td>", wb["q_w_m2"].get<double>(), wb["U"].get<double>())) !=
          std::string::npos);
    // One trial only; an unknown trial and the database as the output are refused.
    const fs::path one = db_path.parent_path() / "trial.html";
    fs::remove(one);
    REQUIRE(run_manikin("report --db " + db_path.string() + " " + campaign + " " + one.string() + " --trial c02-r1").exit_code == 0);
    std::ifstream in1(one);
    const std::string html1((std::istreambuf_iterator<char>(in1)), std::istreambuf_iterator<char>());
    CHECK(html1.find("Trial c02-r1") != std::string::npos);
    CHECK(html1.find("Trial c01-r1") == std::string::npos);
    CHECK(run_manikin("report --db " + db_path.string() + " " + campaign + " " + (db_path.parent_path() / "x.html").string() +
                      " --trial c09-r9").exit_code == 2);
    CHECK(run_manikin("report --db " + db_path.string() + " " + campaign + " " + db_path.string() + " --force").exit_code != 0);
    CHECK(fs::file_size(db_path) > 100000);  // still the database
}
