// `manikin replay`: a candump -l capture through the driver, printed and recorded.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "store/database.hpp"
#include "run_cli.hpp"

using manikind::test::run_manikin;

TEST_CASE("manikin replay prints the zone values of a hand-written candump -l capture", "[cli][replay]") {
    const auto r = run_manikin(std::string("replay --json ") + MANIKIND_TEST_DATA_DIR "/devices/manikin_capture.log");
    REQUIRE(r.exit_code == 0);
    const auto j = nlohmann::json::parse(r.out);
    CHECK(j["frames"] == 3);
    CHECK(j["channels"]["z05.skin_temp_c"]["value"].get<double>() == Approx(35.01));
    CHECK(j["channels"]["z23.skin_temp_c"]["quality"] == "out_of_range");
}

TEST_CASE("manikin replay --db records the capture as a trial, and refuses a bad line with file and line", "[cli][replay]") {
    const auto dir = std::filesystem::temp_directory_path() / ("manikind-replay-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    const auto db_path = (dir / "replay.db").string();
    {
        // A database the daemon already wrote: the replay must use the same channel units.
        auto daemon_db = manikind::recorder::Database::open(db_path);
        daemon_db.channel_id(daemon_db.device_id("manikin", "can", "socketcan can0"), "z05.skin_temp_c", "°C");
    }
    const auto r = run_manikin(std::string("replay --db ") + db_path + " --campaign bus " + MANIKIND_TEST_DATA_DIR
                               "/devices/manikin_capture.log");
    REQUIRE(r.exit_code == 0);
    auto db = manikind::recorder::Database::open(db_path);
    const auto trials = db.trials(*db.find_campaign("bus"));
    REQUIRE(trials.size() == 1);
    CHECK(trials[0].state == "done");
    CHECK(db.sample_count(trials[0].id) == 12);
    {
        std::ofstream bad(dir / "bad.log");
        bad << "(1718000000.100000) can0 105#AC0D520352034B03\nthis is not candump\n";
    }
    const auto b = run_manikin("replay " + (dir / "bad.log").string() + " 2>&1");
    CHECK(b.exit_code == 2);
    CHECK(b.out.find("bad.log:2") != std::string::npos);
    std::filesystem::remove_all(dir);
}

namespace {

// A scratch folder with a capture of the given lines, removed at the end.
struct Capture {
    std::filesystem::path dir;
    std::string log, db;
    explicit Capture(const std::string& lines) {
        static int counter = 0;
        dir = std::filesystem::temp_directory_path() /
              ("manikind-replay-bad-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        std::filesystem::remove_all(dir);
        std::filesystem::create_directories(dir);
        log = (dir / "cap.log").string();
        db = (dir / "replay.db").string();
        std::ofstream(log) << lines;
    }
    ~Capture() { std::filesystem::remove_all(dir); }
    manikind::test::CliResult replay(const std::string& options = "") const {
        return run_manikin("replay " + options + " --db " + db + " --campaign bus " + log + " 2>&1");
    }
};

constexpr const char* kZone5 = " can0 105#AC0D520352034B03\n";

}  // namespace

TEST_CASE("manikin replay refuses a stamp that is not a time, naming file and line, and stores nothing", "[cli][replay]") {
    for (const std::string stamp : {"nan", "inf", "99999999999999999999.2", "-0.9", "1e300"}) {
        INFO(stamp);
        const Capture c(std::string("(1718000000.100000)") + kZone5 + "(" + stamp + ")" + kZone5);
        const auto r = c.replay();
        CHECK(r.exit_code == 2);
        CHECK(r.out.find("cap.log:2: time stamp") != std::string::npos);
        CHECK(!std::filesystem::exists(c.db));  // checked before the database is even opened
    }
}

TEST_CASE("manikin replay refuses a stamp going backwards, naming both lines, and stores nothing", "[cli][replay]") {
    const Capture c(std::string("(1718000001.000000)") + kZone5 + "# a comment\n(1718000000.100000)" + kZone5);
    const auto r = c.replay();
    CHECK(r.exit_code == 2);
    CHECK(r.out.find("cap.log:3: time stamp 1718000000.100000 s is before 1718000001.000000 s on line 1") != std::string::npos);
    CHECK(!std::filesystem::exists(c.db));
}

TEST_CASE("manikin replay skips identical duplicate frames and prints what it stores", "[cli][replay]") {
    const std::string frame = std::string("(1718000000.100000)") + kZone5;
    const Capture c(frame + frame + frame);
    const auto r = c.replay();
    REQUIRE(r.exit_code == 0);
    CHECK(r.out.find("1 frames, 2 identical duplicates skipped, 4 samples stored") != std::string::npos);
    auto db = manikind::recorder::Database::open(c.db);
    const auto trials = db.trials(*db.find_campaign("bus"));
    REQUIRE(trials.size() == 1);
    CHECK(db.sample_count(trials[0].id) == 4);
    const auto j = run_manikin("replay --json " + c.log);
    REQUIRE(j.exit_code == 0);
    const auto doc = nlohmann::json::parse(j.out);
    CHECK(doc["frames"] == 1);
    CHECK(doc["duplicate_frames"] == 2);
    CHECK(doc["samples"] == 4);
}

TEST_CASE("manikin replay refuses two different readings of one zone at one stamp and stores nothing", "[cli][replay]") {
    const Capture c(std::string("(1718000000.100000)") + kZone5 + "(1718000000.100000) can0 105#AD0D4E034E034B03\n");
    const auto r = c.replay();
    CHECK(r.exit_code == 2);
    CHECK(r.out.find("cap.log:2: a second reading of z05.skin_temp_c at the time stamp of line 1") != std::string::npos);
    CHECK(!std::filesystem::exists(c.db));
}
