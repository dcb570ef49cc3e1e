// The CLI's small cuts a textile lab met on its first day (issue 64 part 8), each as the lab typed it.
#include <catch2/catch.hpp>

#include <signal.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "../daemon/daemon_process.hpp"
#include "run_cli.hpp"
#include "store/database.hpp"

namespace fs = std::filesystem;

TEST_CASE("clothing: the replicate criteria are given in percent, as every output prints them, and a fraction is refused "
          "naming the unit",
          "[cli][clothing]") {
    const auto help = manikind::test::run_manikin("clothing --help");
    CHECK_THAT(help.out, Catch::Contains("in % (5 = 5 %)") && Catch::Contains("in % (10 = 10 %)"));
    // 0.05 typed as a fraction would silently mean 0.05 %: refused with the option's range.
    const auto r = manikind::test::run_manikin("clothing /nowhere --cv-limit-insulation 0.05 2>&1");
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.out, Catch::Contains("--cv-limit-insulation"));
}

TEST_CASE("clothing: a --baseline that cannot be read is named as the baseline", "[cli][clothing]") {
    const fs::path dir = fs::temp_directory_path() / ("manikind-cuts-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    REQUIRE(manikind::test::run_manikin("simulate-campaign --out " + (dir / "c").string() + " --replicates 1 --seed 3 > /dev/null")
                .exit_code == 0);
    const auto r = manikind::test::run_manikin("clothing " + (dir / "c").string() + " --baseline " + (dir / "nude").string() +
                                               " --json");
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.out, Catch::Contains("--baseline '" + (dir / "nude").string() + "' (the nude manikin's campaign)"));
    fs::remove_all(dir);
}

TEST_CASE("notes --db reads the lab notebook from the database with no daemon running, trials by their export name",
          "[cli][notes]") {
    const fs::path dir = fs::temp_directory_path() / ("manikind-cuts-notes-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const auto db_path = dir / "lab.db";
    {
        auto db = manikind::recorder::Database::open(db_path);
        const auto campaign = db.create_campaign("astm-0425", "{}");
        const auto first = db.add_case(campaign, "case 1", R"({"id": 3})", 0);
        const auto trial = db.create_trial(campaign, first, 2);
        db.add_note({0, campaign, std::nullopt, 1'700'000'000'000'000'000, "ana", "operator", "Ana ran it"});
        db.add_note({0, campaign, trial, 1'700'000'060'000'000'000, "ben", "ensemble", "coverall #3"});
    }
    // Nothing listens on the socket: the database alone answers.
    const std::string common = "notes --socket " + (dir / "none.sock").string() + " --db " + db_path.string() + " --campaign astm-0425";
    const auto text = manikind::test::run_manikin(common);
    CHECK(text.exit_code == 0);
    CHECK_THAT(text.out, Catch::Contains("Ana ran it") && Catch::Contains("c03-r2") && Catch::Contains("coverall #3"));
    const auto json = nlohmann::json::parse(manikind::test::run_manikin(common + " --json").out);
    REQUIRE(json.size() == 2);
    CHECK(json[1]["trial"] == "c03-r2");
    CHECK(json[0]["trial_id"].is_null());
    const auto missing = manikind::test::run_manikin("notes --db " + db_path.string() + " --campaign nope --json");
    CHECK(missing.exit_code == 2);
    CHECK_THAT(missing.out, Catch::Contains("no campaign named 'nope'"));
    fs::remove_all(dir);
}

TEST_CASE("manikin ack and manikin shelve act on an open alarm from the terminal, recorded with the Unix user",
          "[cli][alarms]") {
    const fs::path dir = fs::temp_directory_path() / ("manikind-cuts-ack-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string socket = (dir / "d.sock").string();
    // The real clock: a shelf of half an hour must not end between two commands, as it would on
    // the virtual clock, which runs as fast as the CPU.
    auto d = manikind::test::DaemonProcess::spawn({std::string(MANIKIND_BIN_DIR) + "/manikind", "--socket", socket,
                                                   "--database", (dir / "d.db").string(), "--campaign",
                                                   std::string(MANIKIND_CONFIG_DIR) + "/campaign-example.toml"});
    REQUIRE(d.read_until("control socket"));
    // An abort is an alarm (MINOR) until someone acknowledges it.
    REQUIRE(manikind::test::run_manikin("campaign abort --reason 'probe fell off' --socket " + socket + " > /dev/null").exit_code == 0);
    auto open_alarm = [&](const std::string& kind) {
        for (const auto& a : nlohmann::json::parse(manikind::test::run_manikin("alarms --json --socket " + socket).out))
            if (a.value("kind", "") == kind) return a;
        return nlohmann::json();
    };
    const auto abort_alarm = open_alarm("abort");
    REQUIRE(abort_alarm.is_object());
    const auto id = std::to_string(abort_alarm["id"].get<long long>());
    // Shelving: bounded (at most 8 h), refused for an alarm that does not exist (exit 4).
    CHECK(manikind::test::run_manikin("shelve " + id + " --hours 9 --socket " + socket + " 2>/dev/null").exit_code == 2);
    CHECK(manikind::test::run_manikin("shelve 999999 --socket " + socket + " 2>/dev/null").exit_code == 4);
    const auto shelved = manikind::test::run_manikin("shelve " + id + " --hours 0.5 --socket " + socket);
    CHECK(shelved.exit_code == 0);
    CHECK_THAT(shelved.out, Catch::Contains("alarm " + id + " shelved for 0.5 h"));
    const auto on_shelf = open_alarm("abort");
    REQUIRE(on_shelf.is_object());
    CHECK(on_shelf.value("state", "") == "SHELVED");
    CHECK(on_shelf.value("shelved_by", std::string()).find("uid") != std::string::npos);  // who: the Unix user
    // Acknowledged (on the shelf it stays open until the shelf ends): who is recorded.
    const auto ack = manikind::test::run_manikin("ack " + id + " --socket " + socket);
    CHECK(ack.exit_code == 0);
    CHECK_THAT(ack.out, Catch::Contains("alarm " + id + " acknowledged"));
    const auto acked = open_alarm("abort");
    REQUIRE(acked.is_object());
    CHECK(acked.value("acknowledged", false));
    CHECK(acked.value("acknowledged_by", std::string()).find("uid") != std::string::npos);
    ::kill(d.pid(), SIGTERM);
    d.wait();
    fs::remove_all(dir);
}
