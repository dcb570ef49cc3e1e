// `manikin replay`: a candump -l capture through the driver, printed and recorded.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "daemon/core/recorder/database.hpp"
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
