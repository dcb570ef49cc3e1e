// `manikin analyze` on bad recordings: a bad-input error (status 2) naming file, line and
// field, never "internal error" (issue 17).
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "run_cli.hpp"

using manikind::test::run_manikin;
namespace fs = std::filesystem;

namespace {

// good-2zone copied to a scratch folder, with `from` replaced by `to` in `file`.
struct BrokenCampaign {
    fs::path dir;
    BrokenCampaign(const std::string& file, const std::string& from, const std::string& to) {
        static int counter = 0;
        dir = fs::temp_directory_path() / ("manikind-analyze-bad-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        fs::remove_all(dir);
        fs::copy(MANIKIND_TEST_DATA_DIR "/recordings/good-2zone", dir, fs::copy_options::recursive);
        std::ifstream in(dir / file, std::ios::binary);
        std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        in.close();
        const auto at = text.find(from);
        REQUIRE(at != std::string::npos);
        text.replace(at, from.size(), to);
        std::ofstream(dir / file, std::ios::binary | std::ios::trunc) << text;
    }
    ~BrokenCampaign() { fs::remove_all(dir); }
};

}  // namespace

TEST_CASE("manikin analyze: bad input is status 2 naming file, line and field, never an internal error", "[cli][analyze]") {
    struct Case {
        const char* file;
        const char* from;
        const char* to;
        const char* expected;  // file:line:column (field ...)
    };
    const Case cases[] = {
        {"campaign.json", "\"skin_setpoint_c\": 35.0", "\"skin_setpoint_c\": 1e400", "campaign.json:37:26 (field 'skin_setpoint_c')"},
        {"campaign.json", "\"trials/c09-r3.csv\"", "\"trials\"", "campaign.json:52:7 (field 'trials[2].file')"},
        {"campaign.json", "\"replicate\": 3", "\"replicate\": -1", "campaign.json:51:7 (field 'trials[2].replicate')"},
        {"trials/c09-r3.csv", "5,39.6,38.3,35.01,35.00,14,25", "5,39.6,38.3,35.01,35.00,14,1e308",
         "c09-r3.csv:3:28 (field 'z02_flux_w_m2')"},
    };
    for (const auto& c : cases) {
        INFO(c.to);
        const BrokenCampaign campaign(c.file, c.from, c.to);
        const auto r = run_manikin("analyze " + campaign.dir.string() + " 2>&1");
        CHECK(r.exit_code == 2);
        CHECK(r.out.find(c.expected) != std::string::npos);
        CHECK(r.out.find("internal error") == std::string::npos);
        CHECK(r.out.find("-nan") == std::string::npos);
    }
}
