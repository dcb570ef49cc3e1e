// analyze_campaign_streaming (a few trials in memory at a time, two parsed at once) against the in-memory
// analyze_campaign(read_campaign(folder)): the same result to the last bit, the same errors.
#include <algorithm>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>

#include <catch2/catch.hpp>

#include "analysis/analyze.hpp"
#include "analysis/input_error.hpp"
#include "analysis/recording.hpp"
#include "analysis/synthetic.hpp"
#include "tests/analysis/short_window.hpp"
#include "tests/analysis/temp_dir.hpp"

namespace an = manikind::analysis;

namespace {

std::string streamed_recording(const std::string& name) { return std::string(MANIKIND_TEST_DATA_DIR) + "/recordings/" + name; }

// Both paths on one folder; every field of the result is in its JSON, table or CSV form.
void check_same_result(const std::filesystem::path& folder, const an::AnalysisOptions& o) {
    const auto in_memory = an::analyze_campaign(an::read_campaign(folder), o);
    const auto streamed = an::analyze_campaign_streaming(folder, {}, o);
    CHECK(an::to_json(streamed).dump() == an::to_json(in_memory).dump());
    CHECK(an::format_table(streamed) == an::format_table(in_memory));
    CHECK(an::format_csv(streamed) == an::format_csv(in_memory));
    // The command's output, written case by case, is dump(2) of the whole document.
    auto whole = an::to_json(in_memory);
    whole["heat_flux_sign"] = "positive out";
    std::ostringstream written;
    an::write_json(written, streamed, 2, {{"heat_flux_sign", "positive out"}});
    CHECK(written.str() == whole.dump(2));
    std::ostringstream unindented;  // indent 0: newlines, no spaces
    an::write_json(unindented, streamed, 0);
    CHECK(unindented.str() == an::to_json(in_memory).dump(0));
}

std::string error_text(const std::function<void()>& read) {
    try {
        read();
    } catch (const an::InputError& e) {
        return e.what();
    }
    return "no error";
}

// Keeps the first `rows` samples: a trial shorter than the steady window (excluded as partial).
void truncate(an::TrialData& d, std::size_t rows) {
    for (auto* v : {&d.t_s, &d.air_temp_c, &d.air_rh_pct, &d.air_speed_m_s, &d.wall_temp_c})
        v->resize(std::min(rows, v->size()));  // air speed and wall may be absent (empty)
    for (auto* zones : {&d.skin_temp_c, &d.heat_flux_w_m2})
        for (auto& v : *zones) v.resize(rows);
}

}  // namespace

TEST_CASE("streaming analysis equals the in-memory one on good-2zone") {
    check_same_result(streamed_recording("good-2zone"), manikind::test::short_window());
    check_same_result(streamed_recording("empty-trial"), manikind::test::short_window());
    auto o = manikind::test::short_window();
    o.type_b_correlation = an::TypeBCorrelation::uncorrelated;
    o.coverage = an::Coverage::replicates_t;
    o.include_unsteady = true;
    check_same_result(streamed_recording("good-2zone"), o);
}

TEST_CASE("streaming analysis equals the in-memory one on a synthetic campaign of several cases") {
    an::SyntheticTrialOptions base;
    base.duration_s = 3600.0;  // 60 min: settled over the final 30 min, and short for the test
    auto campaign = an::make_synthetic_campaign(4, 3, base);
    // Out of file order, so the per-case sort by replicate matters; a partial trial; a case
    // with no usable trial; replicates that disagree on wettedness.
    std::reverse(campaign.trials.begin(), campaign.trials.end());
    for (auto& t : campaign.trials) {
        if (t.info.id == "c02-r2" || t.info.case_id == 4) truncate(t.data, 100);
        if (t.info.id == "c03-r1") t.info.wettedness = 0.5;
    }
    manikind::test::TempDir dir;
    an::write_campaign(dir.path, campaign);

    const auto streamed = an::analyze_campaign_streaming(dir.path);
    CHECK(streamed.cases.size() == 3);
    CHECK(streamed.unanalysed_cases.size() == 1);
    check_same_result(dir.path, {});
}

TEST_CASE("streaming analysis: a bad trial file gives read_campaign's error text") {
    // In each bad-* campaign the first trials are good: the streaming path has summarised them
    // when it reaches the bad one, and must still throw the same error.
    for (const char* folder : {"bad-non-numeric", "bad-column-count", "bad-time-backwards", "bad-unknown-zone",
                               "bad-duplicate-id", "bad-missing-file", "no-such-campaign"}) {
        INFO(folder);
        const std::string expected = error_text([&] { (void)an::read_campaign(streamed_recording(folder)); });
        CHECK(expected != "no error");
        CHECK(error_text([&] { (void)an::analyze_campaign_streaming(streamed_recording(folder)); }) == expected);
    }
    CHECK(error_text([] { (void)an::analyze_campaign_streaming(streamed_recording("bad-non-numeric")); })
              .find("c09-r3.csv:4:29 (field 'z02_flux_w_m2'): expected a number, found 'abc'") != std::string::npos);
}

TEST_CASE("read_campaign_metadata reads campaign.json only, read_trial_data one trial") {
    const auto whole = an::read_campaign(streamed_recording("good-2zone"));
    const auto metadata = an::read_campaign_metadata(streamed_recording("good-2zone"));
    CHECK(metadata.name == whole.name);
    CHECK(metadata.warnings == whole.warnings);
    CHECK(metadata.zone_map.size() == whole.zone_map.size());
    REQUIRE(metadata.trials.size() == whole.trials.size());
    for (std::size_t i = 0; i < metadata.trials.size(); ++i) {
        CHECK(metadata.trials[i].info.id == whole.trials[i].info.id);
        CHECK(metadata.trials[i].data.rows() == 0);
        const auto data = an::read_trial_data(streamed_recording("good-2zone"), metadata, metadata.trials[i].info);
        CHECK(data.t_s == whole.trials[i].data.t_s);
        CHECK(data.heat_flux_w_m2 == whole.trials[i].data.heat_flux_w_m2);
    }
    // A campaign.json problem is found before any trial is read.
    CHECK_THROWS_AS(an::read_campaign_metadata(streamed_recording("bad-duplicate-id")), an::InputError);
    CHECK_NOTHROW(an::read_campaign_metadata(streamed_recording("bad-non-numeric")));
}

TEST_CASE("write_json of a campaign without cases equals dump") {
    an::CampaignResult empty;
    std::ostringstream written;
    an::write_json(written, empty, 4);
    CHECK(written.str() == an::to_json(empty).dump(4));
}

TEST_CASE("aggregate_trials refuses results that do not match the trials") {
    const auto metadata = an::read_campaign_metadata(streamed_recording("good-2zone"));
    CHECK_THROWS_AS(an::aggregate_trials(metadata, {}), std::invalid_argument);
}

TEST_CASE("streaming analysis: of two bad trials read at once, the first in campaign order is the error, as one thread "
          "reads them") {
    an::SyntheticTrialOptions base;
    base.duration_s = 3600.0;
    const auto campaign = an::make_synthetic_campaign(2, 3, base);
    manikind::test::TempDir dir;
    an::write_campaign(dir.path, campaign);
    // Trials 3 and 4 are parsed at the same time; the later one is the shorter file to parse, so
    // its error is usually found first.
    {
        std::ofstream later(dir.path / campaign.trials[4].info.file, std::ios::trunc);
        later << "t_s\n";
    }
    {
        std::ofstream earlier(dir.path / campaign.trials[3].info.file, std::ios::app);
        earlier << "oops\n";
    }
    const std::string expected = error_text([&] { (void)an::read_campaign(dir.path); });
    CHECK(expected.find(campaign.trials[3].info.file) != std::string::npos);
    for (int run = 0; run < 20; ++run) CHECK(error_text([&] { (void)an::analyze_campaign_streaming(dir.path); }) == expected);
}
