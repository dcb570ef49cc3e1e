// The daemon's own store and forward (`[archive] postgresql`, issue 19): a simulated campaign
// recorded by the daemon on the virtual clock and forwarded by the background thread while a real
// PostgreSQL 15 server is stopped and restarted twice, once between passes and once in the
// middle of one. Every sample arrives exactly once and the archive's sums equal the SQLite file's.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <vector>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "archive/background.hpp"
#include "daemon/config.hpp"
#include "tests/archive/archive_checks.hpp"
#include "tests/archive/pg_server.hpp"
#include "tests/daemon/daemon_fixture.hpp"
#include "tests/daemon/daemon_process.hpp"

namespace {

using manikind::archive::BackgroundForwarder;
using manikind::archive::ChunkCommitted;
using manikind::archive::ForwardingOptions;
using manikind::test::DaemonFixture;
using manikind::test::PgServer;

struct Notices {
    std::mutex m;
    std::vector<std::pair<std::string, std::string>> seen;  // severity, message
    void add(const std::string& severity, const std::string& message) {
        std::lock_guard lk(m);
        seen.emplace_back(severity, message);
    }
    int count(const std::string& severity, const std::string& part) {
        std::lock_guard lk(m);
        int n = 0;
        for (const auto& [s, msg] : seen) n += s == severity && msg.find(part) != std::string::npos;
        return n;
    }
};

}  // namespace

TEST_CASE("the daemon forwards a campaign by itself while the server is stopped and restarted twice: every sample "
          "arrives exactly once",
          "[archive][daemon]") {
    PgServer pg;
    DaemonFixture fx;
    auto& daemon = fx.daemon();

    int stop_server_after_chunks = 0;  // >0: the forwarder's thread stops the server after that many chunks
    ForwardingOptions fo;
    fo.database = daemon.database_path();
    fo.conninfo = pg.conninfo();
    fo.lab_id = "lab-a";
    // Passes only when the test asks (forward_now), so the outages fall where the test puts them.
    fo.interval = std::chrono::hours(1);
    fo.max_retry_delay = std::chrono::hours(1);
    fo.chunk_rows = 2000;
    fo.after_chunk = [&](const ChunkCommitted&) {
        if (stop_server_after_chunks > 0 && --stop_server_after_chunks == 0) pg.stop();
    };
    Notices notices;
    BackgroundForwarder forwarder(fo, [&](const std::string& s, const std::string& m) { notices.add(s, m); });
    daemon.add_status_section("archive", [&] { return forwarder.status_json(); });

    REQUIRE(daemon.start_campaign(manikind::test::quick_plan("forwarded", 35.0)).empty());
    // Round by round, 10 virtual minutes each (~23 000 rows): forward, then the outages.
    int round = 0;
    bool mid_pass_outage_done = false;
    while (daemon.campaign_active()) {
        daemon.run_virtual({}, 600.0);  // returns with the recorder flushed
        ++round;
        INFO("round " << round);
        switch (round) {
        case 2:  // the server goes away between passes and stays away for two passes
            pg.stop();
            CHECK_FALSE(forwarder.forward_now());
            CHECK(daemon.status_json()["archive"]["state"] == "retrying");
            break;
        case 3:
            CHECK_FALSE(forwarder.forward_now());
            break;
        case 4:
            pg.start();
            CHECK(forwarder.forward_now());
            break;
        case 5:  // it goes away in the middle of a pass, after the first committed chunk
            stop_server_after_chunks = 1;
            CHECK_FALSE(forwarder.forward_now());
            mid_pass_outage_done = stop_server_after_chunks == 0;
            pg.start();
            break;
        default:
            CHECK(forwarder.forward_now());
        }
    }
    REQUIRE(round >= 6);  // the campaign outlived both outages
    CHECK(mid_pass_outage_done);
    // Twice at once (the previous pass's session may still hold the lab's lock on the server for
    // a moment): the second pass has nothing new and changes nothing.
    for (int pass = 0; pass < 2; ++pass) {
        const bool ok = forwarder.forward_now();
        INFO("final pass " << pass << ": " << daemon.status_json()["archive"].dump());
        REQUIRE(ok);
    }

    manikind::test::check_archive_equals_sqlite(daemon.database_path(), pg.conninfo());
    const auto status = daemon.status_json()["archive"];
    CHECK(status["state"] == "up to date");
    CHECK(status["failures"] == 3);
    CHECK(status["behind_s"].get<double>() >= 0.0);
    CHECK(status["last_error"].is_null());
    // One warning per outage, not one per failed pass; an info line when each outage ends.
    CHECK(notices.count("warn", "archive forwarding failed") == 2);
    CHECK(notices.count("info", "reachable again") == 2);
    forwarder.stop();
    CHECK(daemon.status_json()["archive"]["state"] == "stopped");
}

TEST_CASE("[archive] settings: a lab id is required, a bad conninfo and a password in a world-readable file are "
          "refused with file and key",
          "[archive][config]") {
    using manikind::config::parse_config;
    using manikind::config::validate;
    auto joined = [](const std::vector<std::string>& problems) {
        std::string all;
        for (const auto& p : problems) all += p + "\n";
        return all;
    };
    auto c = parse_config("[archive]\npostgresql = \"host=/tmp port=5432\"\n", "lab.toml");
    CHECK_THAT(joined(validate(c)), Catch::Contains("archive.lab_id: needed with archive.postgresql"));
    c = parse_config("[archive]\npostgresql = \"host=/tmp port=5432\"\nlab_id = \"lab a\"\n", "lab.toml");
    CHECK_THAT(joined(validate(c)), Catch::Contains("lab.toml:3") && Catch::Contains("'lab a': expected 1 to 64"));
    c = parse_config("[archive]\npostgresql = \"host=/tmp nosuchkey=1\"\nlab_id = \"lab-a\"\n", "lab.toml");
    CHECK_THAT(joined(validate(c)), Catch::Contains("lab.toml:2") && Catch::Contains("does not parse"));
    c = parse_config("[archive]\npostgresql = \"host=/tmp password=hunter2\"\nlab_id = \"lab-a\"\n", "lab.toml");
    c.file_mode = 0644;
    CHECK_THAT(joined(validate(c)), Catch::Contains("holds a password but the file is readable by every user"));
    c.file_mode = 0640;
    CHECK(joined(validate(c)).find("archive") == std::string::npos);
    c = parse_config("[archive]\npostgresql = \"postgresql://archive.example/manikind\"\nlab_id = \"lab-a\"\n"
                     "interval_s = 2.5\n",
                     "lab.toml");
    CHECK(c.archive.interval_s == 2.5);
    CHECK(joined(validate(c)).find("archive") == std::string::npos);
}

TEST_CASE("manikind with [archive] postgresql forwards its campaign and, at a clean exit, everything it recorded",
          "[archive][daemon][process]") {
    PgServer pg;
    const auto dir = std::filesystem::temp_directory_path() / ("manikind-forward-" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    {
        std::ofstream config(dir / "lab.toml");
        config << "[archive]\npostgresql = \"" << pg.conninfo() << "\"\nlab_id = \"lab-b\"\nlab_name = \"Chamber B\"\n";
        std::ofstream plan(dir / "plan.toml");
        plan << "name = \"forwarded\"\nreplicates = 1\ntrial_duration_min = 35\n"
                "[[cases]]\nchamber_temp_c = 35\nchamber_rh_pct = 27\nskin_setpoint_c = 35\nwet = false\n";
    }
    auto child = manikind::test::DaemonProcess::spawn(
        {std::string(MANIKIND_BIN_DIR) + "/manikind", "--virtual", "--config", (dir / "lab.toml").string(), "--database",
         (dir / "b.db").string(), "--socket", (dir / "d.sock").string(), "--campaign", (dir / "plan.toml").string(),
         "--exit-when-done"});
    const int status = child.wait();
    INFO(child.output());
    REQUIRE(WIFEXITED(status));
    REQUIRE(WEXITSTATUS(status) == 0);

    manikind::test::check_archive_equals_sqlite(dir / "b.db", pg.conninfo());
    auto archive = manikind::archive::PgConnection::connect(pg.conninfo());
    CHECK(archive.exec("SELECT name FROM labs WHERE lab_id = 'lab-b'").text(0, 0) == "Chamber B");
    CHECK(archive.exec("SELECT state FROM trials").text(0, 0) == "done");
    CHECK(archive.exec("SELECT count(*) FROM samples").int64(0, 0) > 10000);
    // The forwarder's own notice, stored by the daemon like any event.
    auto db = manikind::recorder::Database::open(dir / "b.db");
    bool noticed = false;
    for (const auto& e : db.events(std::nullopt)) noticed = noticed || (e.kind == "archive" && e.severity == "info");
    CHECK(noticed);
    std::filesystem::remove_all(dir);
}
