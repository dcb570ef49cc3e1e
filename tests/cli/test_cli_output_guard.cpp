// The output guard protects the whole database (issue 60): every command that writes a file
// refuses, --force or not, a database's -wal, -shm and -journal as well as the main file, also
// through a symbolic link, and the campaign folder it reads. Each case is one the finding saw
// lose data: a crashed daemon's -wal (its committed samples live only there) written over by
// export, report, clothing --report and physio --plot; a live database's WAL through a symlinked
// --db; export --archive onto a -wal; physio writing its plot over the recording it reads.
#include <catch2/catch.hpp>

#include <sqlite3.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "run_cli.hpp"

namespace fs = std::filesystem;
using manikind::test::run_manikin;

namespace {

struct GuardDir {
    explicit GuardDir(const std::string& name)
        : path(fs::temp_directory_path() / ("manikind-guard-" + name + "-" + std::to_string(::getpid()))) {
        fs::remove_all(path);
    }
    fs::path path;
    ~GuardDir() { fs::remove_all(path); }
};

struct Lab {
    fs::path db;        // a recorded campaign (the demo's database)
    std::string name;   // its campaign
    fs::path folder;    // the same campaign exported as a campaign folder
};

// One demo campaign per test process, its database and its CSV export.
const Lab& lab() {
    static GuardDir dir("lab");
    static const Lab l = [] {
        REQUIRE(run_manikin("demo --cases 1 --replicates 1 --out " + (dir.path / "demo").string() + " > /dev/null").exit_code == 0);
        Lab out;
        out.db = dir.path / "demo" / "manikind.db";
        const auto campaigns = nlohmann::json::parse(run_manikin("campaigns --json --db " + out.db.string()).out);
        const auto& list = campaigns.is_array() ? campaigns : campaigns.at("campaigns");
        REQUIRE(list.size() == 1);
        out.name = list.at(0).at("name").get<std::string>();
        out.folder = dir.path / "recording";
        REQUIRE(run_manikin("export --db " + out.db.string() + " " + out.name + " " + out.folder.string() + " > /dev/null").exit_code == 0);
        return out;
    }();
    return l;
}

std::string bytes_of(const fs::path& p) {
    if (fs::is_directory(p)) return "(a folder)";
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

void exec(sqlite3* db, const char* sql) {
    char* err = nullptr;
    const int rc = sqlite3_exec(db, sql, nullptr, nullptr, &err);
    INFO((err ? err : ""));
    sqlite3_free(err);
    REQUIRE(rc == SQLITE_OK);
}

// A crashed daemon's database in `dir`: manikind.db with a committed write still only in its
// -wal (no checkpoint), as a daemon killed mid-campaign leaves it. Made by copying both files
// while the writer still holds them.
fs::path crashed_database(const fs::path& dir) {
    fs::create_directories(dir);
    const fs::path live = dir / "writer.db", db = dir / "manikind.db";
    fs::copy_file(lab().db, live, fs::copy_options::overwrite_existing);
    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open(live.c_str(), &raw) == SQLITE_OK);
    exec(raw, "PRAGMA journal_mode=WAL");
    exec(raw, "PRAGMA wal_autocheckpoint=0");
    exec(raw, "UPDATE campaigns SET name = name");
    fs::copy_file(live, db, fs::copy_options::overwrite_existing);
    fs::copy_file(live.string() + "-wal", db.string() + "-wal", fs::copy_options::overwrite_existing);
    sqlite3_close(raw);
    fs::remove(live);
    REQUIRE(fs::file_size(db.string() + "-wal") > 32);  // a header and at least one committed frame
    return db;
}

// The command is refused as output_refused, its message says why, and nothing was written.
void refused(const std::string& args, const fs::path& target, const std::string& says) {
    INFO(args);
    const bool existed = fs::exists(target);
    const std::string before = existed ? bytes_of(target) : std::string();
    const auto r = run_manikin(args + " --json");
    CHECK(r.exit_code == 2);
    const auto doc = nlohmann::json::parse(r.out, nullptr, false);
    REQUIRE_FALSE(doc.is_discarded());
    CHECK(doc.at("error").at("code") == "output_refused");
    const std::string message = doc.at("error").at("message").get<std::string>();
    INFO(message);
    CHECK(message.find(says) != std::string::npos);
    CHECK(message.find(target.filename().string()) != std::string::npos);
    CHECK(fs::exists(target) == existed);
    if (existed) CHECK(bytes_of(target) == before);
    for (const auto& e : fs::directory_iterator(target.parent_path()))
        CHECK_FALSE(e.path().filename().string().starts_with("."));  // no staging left
}

}  // namespace

TEST_CASE("output guard: --force export report clothing --report and physio --plot never write over a crashed daemon's -wal",
          "[cli][export][hostile]") {
    GuardDir dir("case");
    const fs::path crashed = crashed_database(dir.path / "crashed");
    const fs::path wal = crashed.string() + "-wal";
    const std::string db = " --db " + lab().db.string() + " ";
    refused("export" + db + lab().name + " " + wal.string() + " --format hdf5 --force", wal, "write-ahead log");
    refused("export" + db + lab().name + " " + wal.string() + " --force", wal, "write-ahead log");
    refused("report" + db + lab().name + " " + wal.string() + " --force", wal, "write-ahead log");
    refused("clothing " + lab().folder.string() + " --report " + wal.string() + " --force", wal, "write-ahead log");
    refused("physio " + lab().folder.string() + " --plot " + wal.string() + " --force", wal, "write-ahead log");
    refused("physio" + db + "--campaign " + lab().name + " --plot " + wal.string() + " --force", wal, "write-ahead log");
    // Its -shm and -journal, which do not exist: a write there would become the database's.
    refused("report" + db + lab().name + " " + crashed.string() + "-shm --force", fs::path(crashed.string() + "-shm"),
            "shared-memory index");
    refused("report" + db + lab().name + " " + crashed.string() + "-journal --force", fs::path(crashed.string() + "-journal"),
            "rollback journal");
    // The committed write is still there: the -wal is the database's.
    sqlite3* raw = nullptr;
    REQUIRE(sqlite3_open_v2(crashed.c_str(), &raw, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    sqlite3_stmt* q = nullptr;
    REQUIRE(sqlite3_prepare_v2(raw, "PRAGMA integrity_check", -1, &q, nullptr) == SQLITE_OK);
    REQUIRE(sqlite3_step(q) == SQLITE_ROW);
    CHECK(std::string(reinterpret_cast<const char*>(sqlite3_column_text(q, 0))) == "ok");
    sqlite3_finalize(q);
    sqlite3_close(raw);
}

TEST_CASE("output guard: report through a symlinked --db never writes over the real database's -wal",
          "[cli][export][hostile]") {
    GuardDir dir("case");
    const fs::path crashed = crashed_database(dir.path / "real");
    fs::create_symlink(crashed, dir.path / "lab.db");
    const fs::path wal = crashed.string() + "-wal";
    const std::string via_link = " --db " + (dir.path / "lab.db").string() + " " + lab().name + " ";
    refused("report" + via_link + wal.string() + " --force", wal, "which this command reads");
    refused("export" + via_link + wal.string() + " --format hdf5 --force", wal, "which this command reads");
    // Named through a linked folder as well.
    fs::create_directory_symlink(dir.path / "real", dir.path / "linked");
    refused("report" + via_link + (dir.path / "linked" / "manikind.db-wal").string() + " --force", wal, "which this command reads");
}

TEST_CASE("output guard: export --archive refuses a -wal before it connects", "[cli][export][hostile]") {
    GuardDir dir("case");
    const fs::path wal = crashed_database(dir.path / "crashed").string() + "-wal";
    // Port 1 on the loopback: nothing answers, so only a refusal made before connecting is output_refused.
    refused("export --archive 'host=127.0.0.1 port=1 connect_timeout=2' --lab lab-1 " + lab().name + " " + wal.string() +
                " --format hdf5 --force",
            wal, "write-ahead log");
}

TEST_CASE("output guard: physio and clothing never write into the campaign folder they read", "[cli][hostile]") {
    const fs::path json = lab().folder / "campaign.json";
    refused("physio " + lab().folder.string() + " --plot " + json.string() + " --force", json, "inside the campaign folder");
    refused("clothing " + lab().folder.string() + " --report " + json.string() + " --force", json, "inside the campaign folder");
    // Through a link to the folder.
    GuardDir dir("case");
    fs::create_directories(dir.path);
    fs::create_directory_symlink(lab().folder, dir.path / "linked");
    refused("physio " + (dir.path / "linked").string() + " --plot " + json.string() + " --force", json,
            "inside the campaign folder");
}

TEST_CASE("output guard: analyze thermoreg and reconcile never write over a database or the recording they read",
          "[cli][hostile]") {
    GuardDir dir("case");
    const fs::path crashed = crashed_database(dir.path / "crashed");
    const fs::path wal = crashed.string() + "-wal";
    const std::string folder = lab().folder.string();
    refused("analyze " + folder + " --csv " + crashed.string(), crashed, "SQLite database");
    refused("analyze " + folder + " --csv " + wal.string(), wal, "write-ahead log");
    refused("analyze " + folder + " --plot " + wal.string(), wal, "write-ahead log");
    refused("analyze " + folder + " --png " + crashed.string() + "-shm", fs::path(crashed.string() + "-shm"), "shared-memory index");
    refused("analyze --db " + lab().db.string() + " --campaign " + lab().name + " --csv " + lab().db.string(), lab().db,
            "which this command reads");
    refused("analyze " + folder + " --csv " + (lab().folder / "campaign.json").string(), lab().folder / "campaign.json",
            "inside the campaign folder");
    refused("thermoreg --duration 10min --plot " + wal.string(), wal, "write-ahead log");
    refused("reconcile " + folder + " --simulations 200 --write-twin " + (lab().folder / "campaign.json").string(),
            lab().folder / "campaign.json", "which this command reads");
    refused("reconcile " + folder + " --simulations 200 --plots " + (lab().folder / "trials").string(),
            lab().folder / "trials", "inside the campaign folder");
    CHECK_FALSE(fs::exists(lab().folder / "trials" / "parity.svg"));
}
