// The CLI's small cuts a textile lab met on its first day (issue 64 part 8), each as the lab typed it.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

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
