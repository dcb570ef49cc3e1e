// `manikin config check` fails on a file the daemon would refuse, naming file, line and key;
// `manikin config token` makes a token that check accepts.
#include <catch2/catch.hpp>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <algorithm>

#include "run_cli.hpp"

using manikind::test::run_manikin;

TEST_CASE("manikin config check exits 5 (negative verdict) on a bad register map, with file:line: key on stderr", "[cli][config]") {
    const auto dir = std::filesystem::temp_directory_path() / ("manikind-cli-config-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    const auto file = (dir / "lab.toml").string();
    std::ofstream(file) << "[lab]\nname = \"x\"\n[devices.chamber]\nregister_map = \"/dev/zero\"\n";
    // stderr only: the problems must be where a shell user sees them, not on stdout.
    const auto r = run_manikin("config check " + file + " 2>&1 >/dev/null");
    CHECK(r.exit_code == 5);
    CHECK_THAT(r.out, Catch::Contains(file + ":4:") && Catch::Contains("devices.chamber.register_map: /dev/zero: "));
    CHECK(run_manikin("config check " + file).out.find(": ok") == std::string::npos);
    std::filesystem::remove_all(dir);
}

TEST_CASE("manikin config token prints 64 hex characters, new each time, that config check accepts", "[cli][config]") {
    const auto a = run_manikin("config token");
    const auto b = run_manikin("config token");
    REQUIRE(a.exit_code == 0);
    // (no std::regex: GCC 12 warns maybe-uninitialized inside it under the sanitizer build's -O1)
    REQUIRE(a.out.size() == 65);
    CHECK(a.out.back() == '\n');
    CHECK(std::all_of(a.out.begin(), a.out.end() - 1, [](char ch) { return (ch >= '0' && ch <= '9') || (ch >= 'a' && ch <= 'f'); }));
    CHECK(a.out != b.out);

    const auto dir = std::filesystem::temp_directory_path() / ("manikind-cli-token-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    const auto file = (dir / "lab.toml").string();
    std::ofstream(file) << "[api]\ntoken = \"" << a.out.substr(0, 64) << "\"\n";
    ::chmod(file.c_str(), 0640);
    CHECK(run_manikin("config check " + file).exit_code == 0);
    std::filesystem::remove_all(dir);
}
