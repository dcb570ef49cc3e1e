// manikin-recording/2 (and /1, the hand-made campaigns in tests/data/recordings): round trip,
// the embedded zone map, and bad input that names file, line, column and field.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <catch2/catch.hpp>

#include "analysis/input_error.hpp"
#include "analysis/recording.hpp"
#include "analysis/synthetic.hpp"
#include "analysis/zone_map.hpp"
#include "tests/analysis/temp_dir.hpp"

namespace an = manikind::analysis;
namespace fs = std::filesystem;

namespace {

std::string recordings(const std::string& name) { return std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/" + name; }

using manikind::test::TempDir;

// Same doubles, NaN where NaN.
bool same(const std::vector<double>& a, const std::vector<double>& b) {
    if (a.size() != b.size()) return false;
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (std::isnan(a[i]) != std::isnan(b[i])) return false;
        if (!std::isnan(a[i]) && a[i] != b[i]) return false;
    }
    return true;
}

std::string error_of(const std::string& folder) {
    try {
        (void)an::read_campaign(recordings(folder));
    } catch (const an::InputError& e) {
        return e.what();
    }
    return "no error";
}

}  // namespace

TEST_CASE("embedded andi35 map equals config/andi35_zone_map.csv") {
    std::ifstream in(std::string(MANIKIND_CONFIG_DIR) + "/andi35_zone_map.csv");
    REQUIRE(in);
    const auto file = an::parse_zone_map_csv(in, "andi35_zone_map.csv");
    const auto& built_in = an::andi35_zone_map();
    REQUIRE(file.size() == built_in.size());
    CHECK(built_in.size() == 35);
    for (std::size_t i = 0; i < file.size(); ++i) {
        const auto& a = file.zones[i];
        const auto& b = built_in.zones[i];
        CHECK(a.zone == b.zone);
        CHECK(a.name == b.name);
        CHECK(a.region == b.region);
        CHECK(a.segment == b.segment);
        CHECK(a.side == b.side);
        CHECK(a.area_m2 == b.area_m2);
        CHECK(a.centroid_height_m == b.centroid_height_m);
        CHECK(a.facing == b.facing);
    }
}

TEST_CASE("andi35 regions: head to feet, left and right apart") {
    const auto regions = an::andi35_zone_map().regions();
    const std::vector<std::string> expected{"head",    "chest",     "back",   "pelvis",  "upper_arm_l", "upper_arm_r",
                                            "forearm_l", "forearm_r", "hand_l", "hand_r", "thigh_l",     "thigh_r",
                                            "calf_l",  "calf_r",    "foot_l", "foot_r"};
    CHECK(regions == expected);
    std::size_t zones = 0;
    for (const auto& r : regions) zones += an::andi35_zone_map().zones_in(r).size();
    CHECK(zones == 35);
}

TEST_CASE("round trip: write a campaign, read it back, identical numbers") {
    auto campaign = an::make_synthetic_campaign(2, 3);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    campaign.trials[1].data.heat_flux_w_m2[4][10] = nan;  // an empty cell
    campaign.trials[2].data.air_temp_c[3] = nan;
    campaign.trials[0].data.skin_temp_c[0][0] = 1.0 / 3.0;  // needs all 17 digits
    campaign.trials[0].info.chamber_setpoint_temp_c = 40.0;
    campaign.trials[0].info.chamber_setpoint_rh_pct = 19.0;
    campaign.trials[0].info.started_utc = "2026-06-02T14:05:00Z";
    campaign.instruments["heat_flux_w_m2"] = {0.7, 0.02, an::Distribution::normal_k2};
    TempDir dir;
    an::write_campaign(dir.path, campaign);
    const auto back = an::read_campaign(dir.path);

    CHECK(back.name == campaign.name);
    CHECK(back.zone_map.name == "andi35");
    REQUIRE(back.trials.size() == campaign.trials.size());
    for (std::size_t t = 0; t < back.trials.size(); ++t) {
        const auto& a = campaign.trials[t];
        const auto& b = back.trials[t];
        CHECK(a.info.id == b.info.id);
        CHECK(a.info.case_id == b.info.case_id);
        CHECK(a.info.replicate == b.info.replicate);
        CHECK(a.info.wettedness == b.info.wettedness);
        CHECK(a.info.skin_setpoint_c == b.info.skin_setpoint_c);
        CHECK(a.info.chamber_setpoint_temp_c == b.info.chamber_setpoint_temp_c);
        CHECK(a.info.started_utc == b.info.started_utc);
        CHECK(same(a.data.t_s, b.data.t_s));
        CHECK(same(a.data.air_temp_c, b.data.air_temp_c));
        CHECK(same(a.data.air_rh_pct, b.data.air_rh_pct));
        CHECK(same(a.data.air_speed_m_s, b.data.air_speed_m_s));
        CHECK(same(a.data.wall_temp_c, b.data.wall_temp_c));
        for (std::size_t z = 0; z < 35; ++z) {
            CHECK(same(a.data.skin_temp_c[z], b.data.skin_temp_c[z]));
            CHECK(same(a.data.heat_flux_w_m2[z], b.data.heat_flux_w_m2[z]));
        }
    }
    const auto& spec = back.instruments.at("heat_flux_w_m2");
    CHECK(spec.accuracy == 0.7);
    CHECK(spec.accuracy_of_reading == 0.02);
    CHECK(spec.distribution == an::Distribution::normal_k2);
}

TEST_CASE("format 2 round trip: per-instrument channels with quality, UTC, provenance") {
    auto campaign = an::make_synthetic_campaign(1, 2);
    campaign.channels = {{"datalogger", "ee181_1.air_temp_c", "°C"}, {"manikin", "z01.sweat_rate_g_m2_h", "g/(m² h)"}};
    campaign.provenance = {{"program", "manikind test"}, {"config_sha256", std::string(64, 'a')}};
    const std::int64_t t0_utc_ns = 1795000000123000000;  // 2026-11-18, with milliseconds
    for (auto& trial : campaign.trials) {
        auto& d = trial.data;
        trial.info.t0_utc_ns = t0_utc_ns;
        for (const double t : d.t_s) d.utc_ns.push_back(t0_utc_ns + static_cast<std::int64_t>(t * 1e9));
        d.channel_values.assign(2, std::vector<double>(d.rows(), 0.1));
        d.channel_quality.assign(2, std::vector<std::uint8_t>(d.rows(), 0));
        d.channel_values[0][1] = 22.05;
        d.channel_quality[0][2] = 2;  // out of range, value kept
        d.channel_values[1][3] = std::numeric_limits<double>::quiet_NaN();
        d.channel_quality[1][3] = an::kNoSample;
    }
    TempDir dir;
    an::write_campaign(dir.path, campaign);
    std::ifstream csv(dir.path / "trials" / (campaign.trials[0].info.id + ".csv"));
    std::string header, row1;
    std::getline(csv, header);
    std::getline(csv, row1);
    CHECK(header.starts_with("t_s,utc,air_temp_c,"));
    CHECK(header.ends_with(",datalogger.ee181_1.air_temp_c,datalogger.ee181_1.air_temp_c.q,"
                           "manikin.z01.sweat_rate_g_m2_h,manikin.z01.sweat_rate_g_m2_h.q"));
    CHECK(row1.find(",2026-11-18T") != std::string::npos);

    const auto back = an::read_campaign(dir.path);
    REQUIRE(back.channels.size() == 2);
    CHECK(back.channels[1].unit == "g/(m² h)");
    CHECK(back.provenance.at("config_sha256") == std::string(64, 'a'));
    REQUIRE(back.trials.size() == campaign.trials.size());
    for (std::size_t t = 0; t < back.trials.size(); ++t) {
        const auto& a = campaign.trials[t].data;
        const auto& b = back.trials[t].data;
        CHECK(back.trials[t].info.t0_utc_ns == t0_utc_ns);
        // Millisecond resolution: the synthetic grid is whole seconds, so exact.
        CHECK(a.utc_ns == b.utc_ns);
        for (std::size_t k = 0; k < 2; ++k) {
            CHECK(same(a.channel_values[k], b.channel_values[k]));
            CHECK(a.channel_quality[k] == b.channel_quality[k]);
        }
        CHECK(same(a.heat_flux_w_m2[0], b.heat_flux_w_m2[0]));
    }
}

TEST_CASE("format 2 bad input: an undeclared channel, a bad quality code, a bad UTC time") {
    auto campaign = an::make_synthetic_campaign(1, 1);
    campaign.channels = {{"csat3b", "ux_m_s", "m/s"}};
    auto& d = campaign.trials[0].data;
    for (const double t : d.t_s) d.utc_ns.push_back(static_cast<std::int64_t>(t * 1e9));
    d.channel_values.assign(1, std::vector<double>(d.rows(), 0.25));
    d.channel_quality.assign(1, std::vector<std::uint8_t>(d.rows(), 0));
    TempDir dir;
    an::write_campaign(dir.path, campaign);
    const fs::path csv = dir.path / "trials" / (campaign.trials[0].info.id + ".csv");
    std::ifstream in(csv);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    auto error_with = [&](const std::string& from, const std::string& to) {
        std::string edited = text;
        edited.replace(edited.find(from), from.size(), to);
        std::ofstream(csv, std::ios::trunc) << edited;
        try {
            (void)an::read_campaign(dir.path);
        } catch (const an::InputError& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    CHECK_THAT(error_with("csat3b.ux_m_s,", "csat3b.uy_m_s,"), Catch::Contains(":1:") && Catch::Contains("unknown column"));
    CHECK_THAT(error_with(",0.25,0\n", ",0.25,ok\n"),
               Catch::Contains(":2:") && Catch::Contains("csat3b.ux_m_s.q") && Catch::Contains("quality code"));
    CHECK_THAT(error_with("1970-01-01T00:00:00.000Z", "1970-13-01T00:00:00Z"),
               Catch::Contains(":2:") && Catch::Contains("utc") && Catch::Contains("ISO 8601"));
}

TEST_CASE("ISO 8601 UTC: written with milliseconds, read back, malformed times refused") {
    CHECK(an::iso_utc_ms(0) == "1970-01-01T00:00:00.000Z");
    CHECK(an::iso_utc_ms(1795000000123456789) == "2026-11-18T11:06:40.123Z");
    CHECK(an::parse_iso_utc("2026-11-18T11:06:40.123Z") == 1795000000123000000);
    CHECK(an::parse_iso_utc("2026-11-18T11:06:40Z") == 1795000000000000000);
    CHECK(an::parse_iso_utc("1969-12-31T23:59:59.5Z") == -500000000);
    CHECK_FALSE(an::parse_iso_utc("2026-02-30T00:00:00Z"));
    CHECK_FALSE(an::parse_iso_utc("2026-11-18T11:06:40"));
    CHECK_FALSE(an::parse_iso_utc("2026-11-18T11:06:40.Z"));
    CHECK_FALSE(an::parse_iso_utc(""));
    // outside what int64 nanoseconds hold (found by fuzz_recording: 4274-... overflowed)
    CHECK_FALSE(an::parse_iso_utc("4274-11-18T11:06:40Z"));
    CHECK_FALSE(an::parse_iso_utc("0001-01-01T00:00:00Z"));
    CHECK(an::parse_iso_utc("2261-12-31T23:59:59Z").has_value());
}

TEST_CASE("round trip of an inline zone map") {
    const auto original = an::read_campaign(recordings("good-2zone"));
    CHECK(original.zone_map_inline);
    TempDir dir;
    an::write_campaign(dir.path, original);
    const auto back = an::read_campaign(dir.path);
    REQUIRE(back.zone_map.size() == 2);
    CHECK(back.zone_map.zones[1].name == "back");
    CHECK(back.zone_map.zones[1].area_m2 == 0.3);
    CHECK(same(back.trials[2].data.heat_flux_w_m2[1], original.trials[2].data.heat_flux_w_m2[1]));
}

TEST_CASE("missing instruments fall back to Tables S1-S2 and the configured defaults") {
    const auto c = an::read_campaign(recordings("good-2zone"));
    CHECK(c.instruments.at("air_temp_c").accuracy == 0.2);        // EE181
    CHECK(c.instruments.at("air_rh_pct").accuracy_of_reading == 0.01);
    CHECK(c.instruments.at("wall_temp_c").accuracy == 0.5);       // Type-T
}

TEST_CASE("bad input: a non-numeric cell names file, line, column and field") {
    const auto e = error_of("bad-non-numeric");
    CHECK(e.find("c09-r3.csv:4:29 (field 'z02_flux_w_m2'): expected a number, found 'abc'") != std::string::npos);
}

TEST_CASE("bad input: wrong column count") {
    const auto e = error_of("bad-column-count");
    CHECK(e.find("c09-r3.csv:5:28") != std::string::npos);
    CHECK(e.find("too few fields: found 6, the header has 7 columns") != std::string::npos);
}

TEST_CASE("bad input: time going backwards") {
    const auto e = error_of("bad-time-backwards");
    CHECK(e.find("c09-r3.csv:6:1 (field 't_s'): time goes backwards") != std::string::npos);
}

TEST_CASE("bad input: unknown zone column") {
    const auto e = error_of("bad-unknown-zone");
    CHECK(e.find("c09-r3.csv:1:77 (field 'z03_flux_w_m2'): unknown zone column") != std::string::npos);
}

TEST_CASE("bad input: duplicated trial id points at the second one") {
    const auto e = error_of("bad-duplicate-id");
    CHECK(e.find("campaign.json:") != std::string::npos);
    CHECK(e.find("duplicated trial id 'c09-r1'") != std::string::npos);
    // The second "c09-r1" in the file is the duplicate; find its line by hand.
    std::ifstream in(recordings("bad-duplicate-id") + "/campaign.json");
    std::string line;
    int line_no = 0, hits = 0, dup_line = 0;
    while (std::getline(in, line)) {
        ++line_no;
        if (line.find("\"c09-r1\"") != std::string::npos && ++hits == 2) dup_line = line_no;
    }
    REQUIRE(dup_line > 0);
    CHECK(e.find("campaign.json:" + std::to_string(dup_line) + ":") != std::string::npos);
}

TEST_CASE("bad input: a missing trial file") {
    const auto e = error_of("bad-missing-file");
    CHECK(e.find("c09-r3.csv: cannot open the trial file") != std::string::npos);
}

TEST_CASE("bad input: a trial file that is a directory or a device") {
    // Seen writing fuzz_recording: fopen opens a directory, whose first read failed as a
    // std::runtime_error (an internal error, exit status 1); /dev/zero, a line without end,
    // would have been read until memory ran out.
    TempDir dir;
    fs::create_directories(dir.path / "trials" / "c09-r1.csv");
    auto campaign = nlohmann::json::parse(std::ifstream(recordings("good-2zone") + "/campaign.json"));
    campaign["trials"] = nlohmann::json::array({campaign["trials"][0]});
    std::ofstream(dir.path / "campaign.json") << campaign.dump();
    CHECK_THROWS_WITH(an::read_campaign(dir.path), Catch::Contains("c09-r1.csv") && Catch::Contains("not a regular file"));
    CHECK_THROWS_AS(an::read_trial_csv("/dev/zero", an::andi35_zone_map(), "zero.csv"), an::InputError);
}

TEST_CASE("bad input: a missing campaign folder, bad JSON, wrong format") {
    CHECK(error_of("no-such-campaign").find("no such campaign folder") != std::string::npos);
    TempDir dir;
    fs::create_directories(dir.path);
    {
        std::ofstream(dir.path / "campaign.json") << "{\n  \"format\": \"manikin-recording/1\",\n  \"trials\": [,]\n}\n";
    }
    try {
        (void)an::read_campaign(dir.path);
        FAIL("no error");
    } catch (const an::InputError& e) {
        CHECK(e.line() == 3);
        CHECK(std::string(e.what()).find("invalid JSON") != std::string::npos);
    }
    {
        std::ofstream(dir.path / "campaign.json") << "{\"format\": \"manikin-recording/3\", \"trials\": []}";
    }
    CHECK_THROWS_WITH(an::read_campaign(dir.path), Catch::Contains("unsupported format 'manikin-recording/3'"));
}

TEST_CASE("bad input anywhere means nothing is imported, and good input still reads") {
    // The first two trials of every bad-* campaign are the good ones from good-2zone:
    // read_campaign must throw rather than return them.
    for (const char* folder : {"bad-non-numeric", "bad-column-count", "bad-time-backwards", "bad-unknown-zone",
                               "bad-duplicate-id", "bad-missing-file"}) {
        INFO(folder);
        CHECK_THROWS_AS(an::read_campaign(recordings(folder)), an::InputError);
    }
    const auto good = an::read_campaign(recordings("good-2zone"));
    CHECK(good.trials.size() == 3);
    CHECK(good.trials[0].data.rows() == 7);
}

TEST_CASE("unknown keys in campaign.json are warnings, not errors") {
    TempDir dir;
    auto c = an::read_campaign(recordings("good-2zone"));
    an::write_campaign(dir.path, c);
    std::ifstream in(dir.path / "campaign.json");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.replace(text.find("\"instruments\""), 13, "\"operator\": \"ana\",\n  \"instruments\"");
    std::ofstream(dir.path / "campaign.json") << text;
    const auto back = an::read_campaign(dir.path);
    REQUIRE(back.warnings.size() == 1);
    CHECK(back.warnings[0].find("unknown key 'operator'") != std::string::npos);
}

TEST_CASE("CSV cells: empty and nan are missing samples, inf is an error, CRLF is fine") {
    TempDir dir;
    fs::create_directories(dir.path);
    const auto map = an::read_campaign(recordings("good-2zone")).zone_map;
    const std::string header = "t_s,air_temp_c,air_rh_pct,z01_skin_c,z02_skin_c,z01_flux_w_m2,z02_flux_w_m2\r\n";
    std::ofstream(dir.path / "ok.csv") << header << "0,39.6,,35,35,nan,2\r\n5,+39.6,38,35,35,1,2\r\n10, 39.7 ,38,35,35,-nan,2\r\n";
    const auto d = an::read_trial_csv(dir.path / "ok.csv", map, "ok.csv");
    REQUIRE(d.rows() == 3);
    CHECK(d.air_temp_c[2] == 39.7);  // spaces around a number
    CHECK(std::isnan(d.heat_flux_w_m2[0][2]));
    CHECK_FALSE(std::signbit(d.heat_flux_w_m2[0][2]));  // a written "-nan" is the one NaN
    CHECK(std::isnan(d.air_rh_pct[0]));
    CHECK(std::isnan(d.heat_flux_w_m2[0][0]));
    CHECK(d.air_temp_c[1] == 39.6);
    CHECK(d.heat_flux_w_m2[1][1] == 2.0);
    std::ofstream(dir.path / "inf.csv") << header << "0,39.6,38,35,35,inf,2\n";
    CHECK_THROWS_WITH(an::read_trial_csv(dir.path / "inf.csv", map, "inf.csv"),
                      Catch::Contains("inf.csv:2:17 (field 'z01_flux_w_m2')"));
    std::ofstream(dir.path / "notime.csv") << header << ",39.6,38,35,35,1,2\n";
    CHECK_THROWS_WITH(an::read_trial_csv(dir.path / "notime.csv", map, "notime.csv"),
                      Catch::Contains("notime.csv:2:1 (field 't_s'): the time cell is empty"));
    std::ofstream(dir.path / "missing.csv") << "t_s,air_temp_c,air_rh_pct,z01_skin_c,z02_skin_c,z01_flux_w_m2\n";
    CHECK_THROWS_WITH(an::read_trial_csv(dir.path / "missing.csv", map, "missing.csv"),
                      Catch::Contains("(field 'z02_flux_w_m2'): required column is missing"));
}

TEST_CASE("a long trial streams through chunk boundaries intact") {
    // 75 min at 5 s x 35 zones is ~0.6 MB: several 256 kB chunks, so lines straddle them.
    an::SyntheticTrialOptions o;
    const auto& map = an::andi35_zone_map();
    an::Campaign c;
    c.name = "one";
    c.zone_map = map;
    c.instruments = an::default_instrument_specs();
    an::Trial t;
    t.info.id = "t1";
    t.info.case_id = 1;
    t.info.replicate = 1;
    t.data = an::make_synthetic_trial(map, o);
    c.trials.push_back(t);
    TempDir dir;
    an::write_campaign(dir.path, c);
    REQUIRE(fs::file_size(dir.path / "trials/t1.csv") > 3 * (1u << 18));
    const auto back = an::read_campaign(dir.path);
    CHECK(back.trials[0].data.rows() == 901);
    CHECK(same(back.trials[0].data.heat_flux_w_m2[34], t.data.heat_flux_w_m2[34]));
}

// --- issue 17: bad input everywhere --------------------------------------------------------

namespace {

// A copy of good-2zone with one thing broken in it.
struct BrokenCopy : TempDir {
    explicit BrokenCopy(const fs::path& from = recordings("good-2zone")) { fs::copy(from, path, fs::copy_options::recursive); }
    // Replaces the first `from` in `file` (relative to the campaign) by `to`.
    void edit(const std::string& file, const std::string& from, const std::string& to) const {
        std::ifstream in(path / file, std::ios::binary);
        std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        const auto at = text.find(from);
        REQUIRE(at != std::string::npos);
        text.replace(at, from.size(), to);
        std::ofstream(path / file, std::ios::binary | std::ios::trunc) << text;
    }
    // The InputError's message; any other exception escapes and fails the test.
    std::string error() const {
        try {
            (void)an::read_campaign(path);
        } catch (const an::InputError& e) {
            return e.what();
        }
        return "no error";
    }
};

// "trials/c09-r3.csv" row 2 (line 3) is "5,39.6,38.3,35.01,35.00,14,25".
constexpr const char* kR3 = "trials/c09-r3.csv";
constexpr const char* kR3Row2 = "5,39.6,38.3,35.01,35.00,14,25";

}  // namespace

TEST_CASE("bad input: values outside their physical range name file, line, column and field") {
    struct Case {
        std::string row;   // replaces line 3 of c09-r3.csv
        std::string where;  // "c09-r3.csv:3:<column> (field '<name>')"
    };
    const Case cases[] = {
        {"5,39.6,38.3,35.01,35.00,14,1e308", "c09-r3.csv:3:28 (field 'z02_flux_w_m2'): 1e308 W/m² is outside the physical range -2000..2000 W/m²"},
        {"5,39.6,38.3,35.01,35.00,-2001,25", "c09-r3.csv:3:25 (field 'z01_flux_w_m2'): -2001 W/m²"},
        {"1e300,39.6,38.3,35.01,35.00,14,25", "c09-r3.csv:3:1 (field 't_s'): 1e300 s is outside the physical range 0..1e+07 s"},
        {"5,101,38.3,35.01,35.00,14,25", "c09-r3.csv:3:3 (field 'air_temp_c'): 101 °C"},
        {"5,39.6,101.5,35.01,35.00,14,25", "c09-r3.csv:3:8 (field 'air_rh_pct'): 101.5 %"},
        {"5,39.6,38.3,95,35.00,14,25", "c09-r3.csv:3:13 (field 'z01_skin_c'): 95 °C"},
        {"5,39.6,38.3,35.01,-11,14,25", "c09-r3.csv:3:19 (field 'z02_skin_c'): -11 °C"},
    };
    for (const auto& c : cases) {
        INFO(c.row);
        BrokenCopy copy;
        copy.edit(kR3, kR3Row2, c.row);
        CHECK_THAT(copy.error(), Catch::Contains(c.where));
    }
    // A negative first time: t_s starts at 0.
    BrokenCopy negative;
    negative.edit(kR3, "\n0,39.6", "\n-1,39.6");
    CHECK_THAT(negative.error(), Catch::Contains("c09-r3.csv:2:1 (field 't_s'): -1 s is outside"));
    // The edges of a range are inside it: RH 101 % and flux -2000 W/m² still read.
    BrokenCopy edges;
    edges.edit(kR3, kR3Row2, "5,39.6,101,35.01,35.00,-2000,25");
    CHECK(edges.error() == "no error");
}

TEST_CASE("bad input: air speed, wall temperature and a format-2 channel are range-checked too") {
    auto campaign = an::make_synthetic_campaign(1, 1);
    campaign.channels = {{"csat3b", "ux_m_s", "m/s"}};
    auto& d = campaign.trials[0].data;
    d.air_speed_m_s.assign(d.rows(), 0.25);
    d.wall_temp_c.assign(d.rows(), 22.5);
    d.channel_values.assign(1, std::vector<double>(d.rows(), 0.125));
    d.channel_quality.assign(1, std::vector<std::uint8_t>(d.rows(), 0));
    TempDir dir;
    an::write_campaign(dir.path, campaign);
    REQUIRE_NOTHROW(an::read_campaign(dir.path));
    const std::string csv = "trials/" + campaign.trials[0].info.id + ".csv";
    auto error_with = [&](const std::string& from, const std::string& to) {
        BrokenCopy copy(dir.path);
        copy.edit(csv, from, to);
        return copy.error();
    };
    CHECK_THAT(error_with(",0.25,", ",61,"), Catch::Contains(":2:") && Catch::Contains("(field 'air_speed_m_s'): 61 m/s"));
    CHECK_THAT(error_with(",22.5,", ",151,"), Catch::Contains(":2:") && Catch::Contains("(field 'wall_temp_c'): 151 °C"));
    CHECK_THAT(error_with(",0.125,", ",2e9,"),
               Catch::Contains(":2:") && Catch::Contains("(field 'csat3b.ux_m_s'): 2e9 m/s is outside the physical range -1e+09..1e+09 m/s"));
}

TEST_CASE("bad input: case below 0 and replicate below 1 name campaign.json, the key's line and the field") {
    BrokenCopy replicate;
    replicate.edit("campaign.json", "\"replicate\": 3", "\"replicate\": -1");
    CHECK_THAT(replicate.error(),
               Catch::Contains("campaign.json:51:7 (field 'trials[2].replicate'): must be within 1..2147483647, found -1"));
    BrokenCopy zero;
    zero.edit("campaign.json", "\"replicate\": 1", "\"replicate\": 0");
    CHECK_THAT(zero.error(), Catch::Contains("(field 'trials[0].replicate'): must be within 1.."));
    BrokenCopy case_id;
    case_id.edit("campaign.json", "\"case\": 9", "\"case\": -3");
    CHECK_THAT(case_id.error(), Catch::Contains("campaign.json:34:7 (field 'trials[0].case'): must be within 0.."));
    BrokenCopy huge;
    huge.edit("campaign.json", "\"case\": 9", "\"case\": 99999999999");
    CHECK_THAT(huge.error(), Catch::Contains("(field 'trials[0].case'): must be within 0..2147483647, found 99999999999"));
}

TEST_CASE("bad input: 1e400 in campaign.json names the file, line, column and key") {
    BrokenCopy copy;
    copy.edit("campaign.json", "\"skin_setpoint_c\": 35.0", "\"skin_setpoint_c\": 1e400");
    CHECK_THAT(copy.error(),
               Catch::Contains("campaign.json:37:26 (field 'skin_setpoint_c'): number 1e400 is out of range"));
}

TEST_CASE("bad input: trial files outside the campaign folder are refused without reading them") {
    SECTION("an absolute path") {
        BrokenCopy copy;
        copy.edit("campaign.json", "\"trials/c09-r3.csv\"", "\"/etc/passwd\"");
        const auto e = copy.error();
        CHECK_THAT(e, Catch::Contains("campaign.json:52:7 (field 'trials[2].file'): '/etc/passwd' must be a path relative"));
        CHECK(e.find("root") == std::string::npos);  // nothing of the file's content
    }
    SECTION("../ leading out") {
        BrokenCopy copy;
        copy.edit("campaign.json", "\"trials/c09-r3.csv\"", "\"trials/../../outside.csv\"");
        CHECK_THAT(copy.error(), Catch::Contains("(field 'trials[2].file'): 'trials/../../outside.csv' leads out of the campaign folder"));
    }
    SECTION("a symbolic link to a file outside") {
        BrokenCopy copy;
        TempDir outside;
        fs::create_directories(outside.path);
        fs::copy_file(copy.path / kR3, outside.path / "elsewhere.csv");
        fs::remove(copy.path / kR3);
        fs::create_symlink(outside.path / "elsewhere.csv", copy.path / kR3);
        CHECK_THAT(copy.error(), Catch::Contains("(field 'trials[2].file'): 'trials/c09-r3.csv' is a link that leads out"));
    }
    SECTION("a symbolic link inside the folder is fine") {
        BrokenCopy copy;
        fs::rename(copy.path / kR3, copy.path / "trials/real.csv");
        fs::create_symlink("real.csv", copy.path / kR3);
        CHECK(copy.error() == "no error");
    }
}

TEST_CASE("bad input: a trial file that is not a regular file is refused before it is opened") {
    SECTION("/dev/zero read directly: refused at once (reading it would never end)") {
        const auto map = an::read_campaign(recordings("good-2zone")).zone_map;
        CHECK_THROWS_WITH(an::read_trial_csv("/dev/zero", map, "/dev/zero"),
                          Catch::Contains("/dev/zero: the trial file is not a regular file"));
    }
    SECTION("/dev/zero in campaign.json: refused as a path outside the folder") {
        BrokenCopy copy;
        copy.edit("campaign.json", "\"trials/c09-r3.csv\"", "\"/dev/zero\"");
        CHECK_THAT(copy.error(), Catch::Contains("(field 'trials[2].file'): '/dev/zero' must be a path relative"));
    }
    SECTION("a FIFO inside the folder (opening it would block)") {
        BrokenCopy copy;
        fs::remove(copy.path / kR3);
        REQUIRE(::mkfifo((copy.path / kR3).c_str(), 0600) == 0);
        CHECK_THAT(copy.error(),
                   Catch::Contains("campaign.json:52:7 (field 'trials[2].file'): 'trials/c09-r3.csv': the trial file is not a regular file"));
    }
    SECTION("campaign.json a FIFO") {
        BrokenCopy copy;
        fs::remove(copy.path / "campaign.json");
        REQUIRE(::mkfifo((copy.path / "campaign.json").c_str(), 0600) == 0);
        CHECK_THAT(copy.error(), Catch::Contains("campaign.json: campaign.json is not a regular file"));
    }
    SECTION("a directory") {
        BrokenCopy copy;
        fs::remove(copy.path / kR3);
        fs::create_directories(copy.path / kR3);
        CHECK_THAT(copy.error(), Catch::Contains("(field 'trials[2].file'): 'trials/c09-r3.csv': the trial file is a directory"));
    }
}

TEST_CASE("a last number without a final newline reads completely") {
    BrokenCopy copy;
    std::ifstream in(copy.path / kR3, std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    in.close();
    REQUIRE(text.ends_with(",14,25\n"));
    text.pop_back();
    std::ofstream(copy.path / kR3, std::ios::binary | std::ios::trunc) << text;
    const auto c = an::read_campaign(copy.path);
    REQUIRE(c.trials[2].data.rows() == 7);
    CHECK(c.trials[2].data.heat_flux_w_m2[1].back() == 25.0);
}

TEST_CASE("the lab notebook travels in campaign.json: written, read back, and a bad note named by its field") {
    TempDir dir;
    auto c = an::read_campaign(recordings("good-2zone"));
    REQUIRE_FALSE(c.trials.empty());
    c.notes.push_back({1780000000250000000, "ana", "operator", "Ana ran it", ""});
    c.notes.push_back({1780000100000000000, "bo", "garment", "sleeve torn,\n\"zone 12\" reads low", c.trials[0].info.id});
    an::write_campaign(dir.path, c);
    const auto back = an::read_campaign(dir.path);
    REQUIRE(back.notes.size() == 2);
    CHECK(back.notes[0].utc_ns == 1780000000250000000);
    CHECK(back.notes[0].trial.empty());
    CHECK(back.notes[1].text == "sleeve torn,\n\"zone 12\" reads low");
    CHECK(back.notes[1].trial == c.trials[0].info.id);
    CHECK(back.warnings.empty());

    // Each bad note is refused with the file and the field.
    std::ifstream in(dir.path / "campaign.json");
    const auto doc = nlohmann::json::parse(in);
    auto refused = [&](const std::function<void(nlohmann::json&)>& spoil) {
        auto bad = doc;
        spoil(bad);
        std::ofstream(dir.path / "campaign.json") << bad.dump(2);
        try {
            (void)an::read_campaign(dir.path);
        } catch (const an::InputError& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    CHECK(refused([](nlohmann::json& j) { j["notes"] = "x"; }).find("(field 'notes'): expected an array") != std::string::npos);
    CHECK(refused([](nlohmann::json& j) { j["notes"][0]["kind"] = "gossip"; }).find("(field 'notes[0].kind')") != std::string::npos);
    CHECK(refused([](nlohmann::json& j) { j["notes"][1]["trial"] = "c99-r9"; }).find("(field 'notes[1].trial'): no trial 'c99-r9'") != std::string::npos);
    CHECK(refused([](nlohmann::json& j) { j["notes"][0]["utc"] = "yesterday"; }).find("(field 'notes[0].utc')") != std::string::npos);
    CHECK(refused([](nlohmann::json& j) { j["notes"][0].erase("author"); }).find("(field 'notes[0].author'): required key is missing") != std::string::npos);
    CHECK(refused([](nlohmann::json& j) { j["notes"][0]["text"] = std::string(4001, 'a'); }).find("4001 bytes") != std::string::npos);
    CHECK(refused([](nlohmann::json& j) { j["notes"][0]["text"] = 7; }).find("(field 'notes[0].text'): expected a string") != std::string::npos);
    CHECK(refused([](nlohmann::json&) {}) == "no error");
}
