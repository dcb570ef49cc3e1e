// Reading a campaign out of the database one trial at a time (issue 36): the streaming CSV and
// HDF5 exports give what the whole-campaign reader gives, also when a later trial records a
// channel the first did not (the earlier trial is written again, its column empty: no sample).
#include <catch2/catch.hpp>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "analysis/analyze.hpp"
#include "analysis/recording.hpp"
#include "store/database.hpp"
#include "store/database_export.hpp"
#include "store/hdf5_export.hpp"

namespace fs = std::filesystem;
namespace rec = manikind::recorder;
namespace an = manikind::analysis;

namespace {

struct TempDir {
    fs::path path = fs::temp_directory_path() / ("manikind-db-export-" + std::to_string(::getpid()));
    TempDir() { fs::remove_all(path); fs::create_directories(path); }
    ~TempDir() { fs::remove_all(path); }
};

// Two done trials of 60 s at 1 Hz: zone 1's skin and flux in both, the WindSonic only in the second.
void build(const fs::path& path) {
    auto db = rec::Database::open(path);
    const auto campaign = db.create_campaign("grow", "{}");
    const auto manikin = db.device_id("manikin", "can", "vcan0");
    const auto sonic = db.device_id("windsonic", "serial", "/dev/ttyS0");
    const auto skin = db.channel_id(manikin, "z01.skin_temp_c", "°C");
    const auto flux = db.channel_id(manikin, "z01.heat_flux_w_m2", "W/m²");
    const auto speed = db.channel_id(sonic, "air_speed_m_s", "m/s");
    const auto case_id = db.add_case(campaign, "case 1", "{\"id\": 1, \"skin_setpoint_c\": 34}", 0);
    for (int t = 0; t < 2; ++t) {
        const auto trial = db.create_trial(campaign, case_id, t + 1);
        const std::int64_t mono0 = t * 1'000'000'000'000LL, utc0 = 1'790'000'000'000'000'000LL + mono0;
        db.add_event(trial, mono0, utc0, "info", "stage", "acquiring");
        std::vector<rec::SampleRow> rows;
        for (int s = 1; s <= 60; ++s) {
            const std::int64_t m = mono0 + s * 1'000'000'000LL, u = utc0 + s * 1'000'000'000LL;
            rows.push_back({trial, skin, m, u, 34.0 + 0.01 * s, 0});
            rows.push_back({trial, flux, m + 1, u, 50.0 + t + 0.1 * s, 0});
            if (t == 1) rows.push_back({trial, speed, m + 2, u, 0.1 + 0.001 * s, 0});
        }
        db.insert_samples(rows);
        db.add_event(trial, mono0 + 61'000'000'000LL, utc0 + 61'000'000'000LL, "info", "stage", "stopping");
        db.set_trial_state(trial, "done", "", utc0 + 61'000'000'000LL);
    }
}

bool same(double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; }

}  // namespace

TEST_CASE("export: read a trial at a time, a channel first recorded by a later trial reaches every trial, as the whole "
          "reader gives it",
          "[store][export]") {
    TempDir dir;
    const fs::path db_path = dir.path / "grow.db";
    build(db_path);
    auto db = rec::Database::open_read_only(db_path);
    const an::Campaign whole = manikind::campaign_from_database(db, "grow");
    REQUIRE(whole.trials.size() == 2);
    REQUIRE(whole.channels.size() == 3);  // the WindSonic too, though trial 1 has none of it

    manikind::CampaignReader reader(db, "grow");
    CHECK(reader.campaign().channels.empty());  // nothing read yet
    const auto first = reader.read(0);
    CHECK(reader.campaign().channels.size() == 2);
    CHECK(first.channel_values.size() == 2);
    const auto g1 = reader.channel_generation();
    (void)reader.read(1);
    CHECK(reader.channel_generation() != g1);  // the WindSonic was added
    CHECK(reader.campaign().channels.size() == 3);

    // The CSV export: trial 1 written again, with the WindSonic's column empty.
    manikind::CampaignReader csv_reader(db, "grow");
    const auto counts = manikind::export_campaign_csv(csv_reader, dir.path / "csv");
    CHECK(counts.rewritten == 1);
    const an::Campaign back = an::read_campaign(dir.path / "csv");
    REQUIRE(back.trials.size() == 2);
    REQUIRE(back.channels.size() == 3);
    for (std::size_t t = 0; t < 2; ++t) {
        const auto& a = whole.trials[t].data;
        const auto& b = back.trials[t].data;
        REQUIRE(a.rows() == b.rows());
        CHECK(a.air_speed_m_s.size() == b.air_speed_m_s.size());
        for (std::size_t k = 0; k < 3; ++k)
            for (std::size_t i = 0; i < a.rows(); ++i) {
                CHECK(same(a.channel_values[k][i], b.channel_values[k][i]));
                CHECK(a.channel_quality[k][i] == b.channel_quality[k][i]);
            }
        for (std::size_t i = 0; i < a.rows(); ++i) CHECK(same(a.heat_flux_w_m2[0][i], b.heat_flux_w_m2[0][i]));
    }
    // Trial 1 has the WindSonic's column, with no sample in it.
    const auto speed_q = back.trials[0].data.channel_quality[2];
    CHECK(std::all_of(speed_q.begin(), speed_q.end(), [](std::uint8_t q) { return q == an::kNoSample; }));

    // The HDF5 export, streamed the same way, holds the same columns in both trials.
    manikind::CampaignReader h5_reader(db, "grow");
    const fs::path h5 = dir.path / "grow.h5";
    {
        manikind::Hdf5CampaignFile file(h5, h5_reader.campaign());
        std::vector<an::TrialResult> summaries;
        for (std::size_t s = 0; s < h5_reader.trial_count(); ++s) {
            const an::Trial trial{h5_reader.campaign().trials[s].info, h5_reader.read(s)};
            summaries.push_back(an::summarize_trial(trial, h5_reader.campaign().zone_map));
            file.write_trial(h5_reader.campaign(), trial.info, trial.data);
        }
        file.write_trial(h5_reader.campaign(), h5_reader.campaign().trials[0].info, h5_reader.read(0));  // again, the final set
        file.finish(an::aggregate_trials(h5_reader.campaign(), summaries));
    }
    const auto column = whole.channels[2].column();
    CHECK(manikind::hdf5_read_uint8(h5, "/trials/c01-r1/" + column + ".q") == whole.trials[0].data.channel_quality[2]);
    CHECK(manikind::hdf5_read_doubles(h5, "/trials/c01-r2/" + column).size() == whole.trials[1].data.rows());
    const auto flux = manikind::hdf5_read_doubles(h5, "/trials/c01-r2/" + whole.channels[1].column());
    REQUIRE(flux.size() == whole.trials[1].data.rows());
    for (std::size_t i = 0; i < flux.size(); ++i) CHECK(same(flux[i], whole.trials[1].data.channel_values[1][i]));
}

TEST_CASE("export: an HDF5 export that fails midway leaves no file behind", "[store][export]") {
    TempDir dir;
    const fs::path db_path = dir.path / "grow.db";
    build(db_path);
    auto db = rec::Database::open_read_only(db_path);
    manikind::CampaignReader reader(db, "grow");
    const fs::path h5 = dir.path / "out.h5";
    {
        manikind::Hdf5CampaignFile file(h5, reader.campaign());
        file.write_trial(reader.campaign(), reader.campaign().trials[0].info, reader.read(0));
        // ... and an error before finish: the file is dropped with its temporary.
    }
    CHECK_FALSE(fs::exists(h5));
    for (const auto& e : fs::directory_iterator(dir.path)) CHECK(e.path().filename().string().find("out.h5") == std::string::npos);
}
