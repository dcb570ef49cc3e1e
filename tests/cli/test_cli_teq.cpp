// `manikin calibrate` and `manikin teq` as a user runs them (issue 65): the calibration file is
// written whole and guarded like every output, a non-uniform calibration campaign is refused with
// nothing written, the diagram never lands on an input, and bad input names file, line and field.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include <fmt/format.h>

#include "run_cli.hpp"
#include "store/hdf5_export.hpp"
#include "tests/analysis/teq_lab.hpp"

namespace fs = std::filesystem;
namespace lab = manikind::test::teq_lab;
using manikind::test::run_manikin;

namespace {

struct TeqDir {
    fs::path path = fs::temp_directory_path() / ("manikind-cli-teq-" + std::to_string(::getpid()));
    TeqDir() { fs::remove_all(path); }
    ~TeqDir() { fs::remove_all(path); }
};

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

}  // namespace

TEST_CASE("cli teq: calibrate writes a guarded calibration file and refuses a non-uniform chamber with nothing written",
          "[cli][teq]") {
    TeqDir dir;
    const lab::Manikin m;
    std::mt19937_64 rng(11);
    const lab::Noise n;
    const lab::LabErrors e;
    lab::round_trip(lab::calibration_campaign(m, e, n, rng), dir.path / "cal");
    lab::round_trip(lab::calibration_campaign(m, e, n, rng, 1.5), dir.path / "warm-walls");
    const auto out = dir.path / "cal.json";

    auto r = run_manikin("calibrate " + (dir.path / "cal").string() + " -o " + out.string() + " --draws 200 > /dev/null");
    REQUIRE(r.exit_code == 0);
    const auto doc = nlohmann::json::parse(slurp(out));
    CHECK(doc["format"] == "manikin-teq-calibration/1");
    CHECK(doc["zones"].size() == 35);

    SECTION("an existing calibration is replaced only with --force") {
        r = run_manikin("calibrate " + (dir.path / "cal").string() + " -o " + out.string() + " --draws 200 --json");
        CHECK(r.exit_code == 2);
        CHECK(nlohmann::json::parse(r.out)["error"]["code"] == "output_refused");
        CHECK(run_manikin("calibrate " + (dir.path / "cal").string() + " -o " + out.string() + " --draws 200 --force > /dev/null")
                  .exit_code == 0);
    }
    SECTION("never into the campaign folder it reads") {
        const auto before = slurp(dir.path / "cal" / "campaign.json");
        r = run_manikin("calibrate " + (dir.path / "cal").string() + " -o " + (dir.path / "cal" / "campaign.json").string() +
                        " --force --json");
        CHECK(r.exit_code == 2);
        CHECK(nlohmann::json::parse(r.out)["error"]["code"] == "output_refused");
        CHECK(slurp(dir.path / "cal" / "campaign.json") == before);
    }
    SECTION("walls 1.5 K above the air: refused naming the case and quantity, no file") {
        const auto refused = dir.path / "refused.json";
        r = run_manikin("calibrate " + (dir.path / "warm-walls").string() + " -o " + refused.string() + " --json");
        CHECK(r.exit_code == 2);
        const auto err = nlohmann::json::parse(r.out)["error"];
        CHECK(err["code"] == "calibration_refused");
        CHECK_THAT(err["message"].get<std::string>(), Catch::Contains("case 2") && Catch::Contains("wall - air = +1.50 K"));
        CHECK_FALSE(fs::exists(refused));
        for (const auto& entry : fs::directory_iterator(dir.path)) CHECK(entry.path().filename().string().rfind(".", 0) != 0);
    }
}

TEST_CASE("cli teq: teq prints per zone teq and writes the comfort diagram and the report but never over an input", "[cli][teq]") {
    TeqDir dir;
    const lab::Manikin m;
    std::mt19937_64 rng(12);
    const lab::Noise n;
    const lab::LabErrors e;
    lab::round_trip(lab::calibration_campaign(m, e, n, rng), dir.path / "cal");
    const auto cabin = lab::cabin_campaign(m, e, n, rng);
    lab::round_trip(cabin.campaign, dir.path / "cabin");
    const auto cal = dir.path / "cal.json";
    REQUIRE(run_manikin("calibrate " + (dir.path / "cal").string() + " -o " + cal.string() + " --draws 200 > /dev/null").exit_code == 0);
    const std::string base = "teq " + (dir.path / "cabin").string() + " --calibration " + cal.string() + " --draws 200";

    auto r = run_manikin(base + " --json");
    REQUIRE(r.exit_code == 0);
    const auto doc = nlohmann::json::parse(r.out);
    REQUIRE(doc["cases"].size() == 1);
    CHECK(doc["cases"][0]["zones"].size() == 35);
    CHECK(doc["neutral_ranges"]["placeholder"] == true);
    const double t = doc["cases"][0]["zones"][0]["teq_c"];
    CHECK(std::abs(t - cabin.teq_c[0]) <= doc["cases"][0]["zones"][0]["U95"].get<double>() + 0.5);

    const auto svg = dir.path / "teq.svg";
    CHECK(run_manikin(base + " --plot " + svg.string() + " > /dev/null").exit_code == 0);
    CHECK_THAT(slurp(svg), Catch::StartsWith("<svg") || Catch::Contains("<svg"));
    CHECK_THAT(slurp(svg), Catch::Contains("neutral range"));

    // The page for the reader: who, what, when, which standard, the diagram inline; under the output guard too.
    const auto page = dir.path / "teq.html";
    CHECK(run_manikin(base + " --report " + page.string() + " > /dev/null").exit_code == 0);
    const std::string html = slurp(page);
    CHECK_THAT(html, Catch::Contains("ISO 14505-2") && Catch::Contains("<svg") && Catch::Contains("calibration") &&
                         Catch::Contains("whole_body") && Catch::Contains("face") && Catch::Contains("placeholders") &&
                         Catch::Contains("manikin 0."));
    r = run_manikin(base + " --report " + page.string() + " --json");
    CHECK(r.exit_code == 2);  // an existing file without --force
    CHECK(slurp(page) == html);
    r = run_manikin(base + " --report " + svg.string() + " --plot " + svg.string() + " --force --json");
    CHECK(r.exit_code == 2);  // the same file for both

    // HDF5 for scripts (issue 65 part 3): the same numbers as --json, per case and part, with units.
    const auto h5 = dir.path / "teq.h5";
    CHECK(run_manikin(base + " --hdf5 " + h5.string() + " > /dev/null").exit_code == 0);
    CHECK(manikind::hdf5_read_string_attribute(h5, "/", "format") == "manikin-teq-hdf5/1");
    const std::string group = "cases/case_" + fmt::format("{:03d}", doc["cases"][0]["case"].get<int>());
    const auto zone_teq = manikind::hdf5_read_doubles(h5, group + "/zones/teq_c");
    const auto zone_u95 = manikind::hdf5_read_doubles(h5, group + "/zones/U95_c");
    REQUIRE(zone_teq.size() == 35);
    REQUIRE(zone_u95.size() == 35);
    // The Monte Carlo draws from a fixed seed: the file's numbers are the JSON's.
    CHECK(zone_teq[0] == Approx(doc["cases"][0]["zones"][0]["teq_c"].get<double>()).epsilon(1e-12));
    CHECK(zone_u95[0] == Approx(doc["cases"][0]["zones"][0]["U95"].get<double>()).epsilon(1e-12));
    CHECK(manikind::hdf5_read_doubles(h5, group + "/whole_body/teq_c").size() == 1);
    CHECK(nlohmann::json::parse(manikind::hdf5_read_string(h5, "teq_json"))["cases"].size() == 1);
    r = run_manikin(base + " --hdf5 " + h5.string() + " --json");
    CHECK(r.exit_code == 2);  // an existing file without --force
    r = run_manikin(base + " --hdf5 " + svg.string() + " --plot " + svg.string() + " --force --json");
    CHECK(r.exit_code == 2);  // the same file as the diagram

    const auto cal_before = slurp(cal);
    r = run_manikin(base + " --plot " + cal.string() + " --force --json");
    CHECK(r.exit_code == 2);
    CHECK(nlohmann::json::parse(r.out)["error"]["code"] == "output_refused");
    CHECK(slurp(cal) == cal_before);
    r = run_manikin(base + " --plot " + (dir.path / "cabin" / "teq.svg").string() + " --json");
    CHECK(r.exit_code == 2);
    CHECK_FALSE(fs::exists(dir.path / "cabin" / "teq.svg"));

    SECTION("a bad cell in a trial CSV names the file and the line") {
        const auto csv = dir.path / "cabin" / "trials" / "c01-r2.csv";
        std::string text = slurp(csv);
        const auto line3 = text.find('\n', text.find('\n') + 1) + 1;
        const auto comma = text.find(',', line3);
        text.replace(line3, comma - line3, "zero");
        std::ofstream(csv, std::ios::binary | std::ios::trunc) << text;
        r = run_manikin(base + " --json");
        CHECK(r.exit_code == 2);
        CHECK_THAT(nlohmann::json::parse(r.out)["error"]["message"].get<std::string>(),
                   Catch::Contains("c01-r2.csv:3") && Catch::Contains("t_s"));
    }
    SECTION("a range file with a bad number names file, line and field") {
        const auto ranges = dir.path / "ranges.csv";
        std::ofstream(ranges) << "part,cold_limit_c,warm_limit_c\nface,20,hot\n";
        r = run_manikin(base + " --ranges " + ranges.string() + " --json");
        CHECK(r.exit_code == 2);
        CHECK_THAT(nlohmann::json::parse(r.out)["error"]["message"].get<std::string>(),
                   Catch::Contains("ranges.csv:2") && Catch::Contains("warm_limit_c"));
    }
}
