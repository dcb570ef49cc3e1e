// A trial binned as it is recorded (TrialBins, issue 36) reads exactly as the same trial read back
// from the database, and is refused (the reader reads the database) wherever the two could differ:
// a reading stored once but offered twice, a second start, a reading after the seal, another grid.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "analysis/recording.hpp"
#include "store/database.hpp"
#include "store/database_export.hpp"
#include "store/trial_bins.hpp"

namespace fs = std::filesystem;
namespace rec = manikind::recorder;
namespace an = manikind::analysis;

namespace {

struct BinsDir {
    fs::path path = fs::temp_directory_path() / ("manikind-trial-bins-" + std::to_string(::getpid()));
    BinsDir() { fs::remove_all(path); fs::create_directories(path); }
    ~BinsDir() { fs::remove_all(path); }
};

constexpr std::int64_t kSecond = 1'000'000'000LL;

struct Built {
    std::int64_t trial = 0;
    std::int64_t start_mono_ns = 0;
    std::vector<rec::SampleRow> offered;  // in the order a daemon would offer them
};

// One done trial: 2 min of settling, then 10 min acquiring; zone 1's skin and flux at jittered
// ~1.3 s, the air probe at ~2.1 s with runs of flagged and of lost (NaN) readings, a channel recorded
// only while settling (it gets a column, all empty), readings in the last period before the start
// (they fall in row 0) and older ones (they do not), and readings after the stop (beyond the grid).
Built build_trial(const fs::path& path) {
    auto db = rec::Database::open(path);
    const auto campaign = db.create_campaign("bins", "{}");
    const auto manikin = db.device_id("manikin", "can", "vcan0");
    const auto logger = db.device_id("datalogger", "modbus-tcp", "127.0.0.1:1502");
    const auto skin = db.channel_id(manikin, "z01.skin_temp_c", "°C");
    const auto flux = db.channel_id(manikin, "z01.heat_flux_w_m2", "W/m²");
    const auto air = db.channel_id(logger, "ee181_1.air_temp_c", "°C");
    const auto settle_only = db.channel_id(logger, "ee181_2.air_temp_c", "°C");
    const auto case_id = db.add_case(campaign, "case 1", "{\"id\": 1, \"skin_setpoint_c\": 34}", 0);
    Built b;
    b.trial = db.create_trial(campaign, case_id, 1);
    const std::int64_t mono0 = 7 * kSecond, utc0 = 1'790'000'000'000'000'000LL;
    b.start_mono_ns = mono0 + 120 * kSecond + 333'000'000;  // not on a reading's time
    const std::int64_t stop = b.start_mono_ns + 600 * kSecond;
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> jitter(-0.2, 0.2), noise(-0.05, 0.05);
    // Each channel's readings in time order; the channels interleaved by time, as devices deliver.
    struct Stream {
        std::int64_t id;
        double period_s;
        double t_s;
    };
    std::vector<Stream> streams{{skin, 1.3, 0.1}, {flux, 1.3, 0.7}, {air, 2.1, 0.4}, {settle_only, 3.0, 0.2}};
    const double end_s = static_cast<double>(stop - mono0) * 1e-9 + 30.0;
    int n_air = 0;
    while (true) {
        Stream* next = nullptr;
        for (auto& s : streams)
            if (s.t_s < end_s && (!next || s.t_s < next->t_s)) next = &s;
        if (!next) break;
        const std::int64_t m = mono0 + static_cast<std::int64_t>(next->t_s * 1e9);
        rec::SampleRow r{b.trial, next->id, m, utc0 + (m - mono0), 0.0, 0};
        if (next->id == skin) r.value = 34.0 + noise(rng);
        if (next->id == flux) r.value = 60.0 + 10 * noise(rng);
        if (next->id == air) {
            r.value = 25.0 + noise(rng);
            // Runs of four (8 s), so some rows hold no good reading: flagged, then lost.
            if (++n_air % 40 < 4) r.quality = 2;
            if (n_air % 60 >= 50 && n_air % 60 < 54) r.value = std::numeric_limits<double>::quiet_NaN();
        }
        if (next->id == settle_only) {
            r.value = 24.0;
            if (m > b.start_mono_ns - 20 * kSecond) next->t_s = end_s;  // stops before the start
        }
        b.offered.push_back(r);
        next->t_s += next->period_s + jitter(rng);
    }
    db.add_event(b.trial, b.start_mono_ns, utc0 + (b.start_mono_ns - mono0), "info", "stage", "acquiring");
    db.insert_samples(b.offered);
    db.add_event(b.trial, stop, utc0 + (stop - mono0), "info", "stage", "stopping");
    db.set_trial_state(b.trial, "done", "", utc0 + (stop - mono0));
    return b;
}

// The bins a daemon would keep: rows offered before the start, the start, the rest.
std::shared_ptr<rec::TrialBins> bins_of(const Built& b, bool seal = true) {
    auto bins = std::make_shared<rec::TrialBins>(5.0);
    bool started = false;
    for (const auto& r : b.offered) {
        if (!started && r.mono_ns > b.start_mono_ns) {
            bins->start(b.start_mono_ns);
            started = true;
        }
        bins->add(r);
    }
    if (seal) bins->seal();
    return bins;
}

bool same(const std::vector<double>& x, const std::vector<double>& y) {
    if (x.size() != y.size()) return false;
    for (std::size_t i = 0; i < x.size(); ++i)
        if (!(x[i] == y[i] || (std::isnan(x[i]) && std::isnan(y[i])))) return false;
    return true;
}

struct Read {
    an::Campaign campaign;
    std::size_t from_recording = 0;
};

Read read(rec::Database& db, const Built& b, std::shared_ptr<const rec::TrialBins> bins) {
    manikind::CampaignReader reader(db, "bins");
    if (bins) reader.use_recorded_bins({{b.trial, std::move(bins)}});
    Read r{manikind::read_whole_campaign(reader), 0};
    r.from_recording = reader.trials_from_recording();
    return r;
}

void require_same(const an::Campaign& x, const an::Campaign& y) {
    REQUIRE(x.trials.size() == 1);
    REQUIRE(y.trials.size() == 1);
    REQUIRE(x.channels.size() == y.channels.size());
    for (std::size_t k = 0; k < x.channels.size(); ++k) CHECK(x.channels[k].name == y.channels[k].name);
    const auto& a = x.trials[0].data;
    const auto& c = y.trials[0].data;
    REQUIRE(a.rows() == c.rows());
    CHECK(same(a.t_s, c.t_s));
    CHECK(a.utc_ns == c.utc_ns);
    CHECK(same(a.air_temp_c, c.air_temp_c));
    REQUIRE(a.skin_temp_c.size() == c.skin_temp_c.size());
    for (std::size_t z = 0; z < a.skin_temp_c.size(); ++z) {
        CHECK(same(a.skin_temp_c[z], c.skin_temp_c[z]));
        CHECK(same(a.heat_flux_w_m2[z], c.heat_flux_w_m2[z]));
    }
    REQUIRE(a.channel_values.size() == c.channel_values.size());
    for (std::size_t k = 0; k < a.channel_values.size(); ++k) CHECK(same(a.channel_values[k], c.channel_values[k]));
    CHECK(a.channel_quality == c.channel_quality);
}

}  // namespace

TEST_CASE("trial bins: binned while recording reads bit for bit as the trial read back from the database", "[store][export]") {
    BinsDir dir;
    const auto b = build_trial(dir.path / "m.db");
    auto db = rec::Database::open(dir.path / "m.db");
    const auto from_db = read(db, b, nullptr);
    REQUIRE(from_db.from_recording == 0);
    // The trial exercises what the grid does at its edges: a reading in the period before the
    // start lands in row 0, a flagged and a lost one are in it, a channel only seen settling has
    // a column and no value.
    const auto& d = from_db.campaign.trials[0].data;
    CHECK(d.rows() == 121);
    REQUIRE(d.channel_quality.size() == 4);
    bool flagged = false, lost = false;
    for (const auto& q : d.channel_quality)
        for (const auto v : q) flagged |= v == 2, lost |= v == 3;
    CHECK(flagged);
    CHECK(lost);

    for (const bool seal : {true, false}) {
        const auto live = read(db, b, bins_of(b, seal));
        CHECK(live.from_recording == 1);
        require_same(live.campaign, from_db.campaign);
    }
}

TEST_CASE("trial bins: refused wherever they could differ from the database, which is then read", "[store][export]") {
    BinsDir dir;
    const auto b = build_trial(dir.path / "m.db");
    auto db = rec::Database::open(dir.path / "m.db");
    const auto from_db = read(db, b, nullptr);

    SECTION("a reading offered twice, stored once (a re-sent duplicate)") {
        auto bins = std::make_shared<rec::TrialBins>(5.0);
        bool started = false;
        for (const auto& r : b.offered) {
            if (!started && r.mono_ns > b.start_mono_ns) bins->start(b.start_mono_ns), started = true;
            bins->add(r);
            if (&r == &b.offered[b.offered.size() / 2]) bins->add(r);
        }
        const auto got = read(db, b, bins);
        CHECK(got.from_recording == 0);
        require_same(got.campaign, from_db.campaign);
    }
    SECTION("a reading after the seal") {
        auto bins = bins_of(b);
        bins->add(b.offered.back());
        CHECK_FALSE(bins->usable());
        CHECK(read(db, b, bins).from_recording == 0);
    }
    SECTION("a second start") {
        auto bins = bins_of(b, false);
        bins->start(b.start_mono_ns);
        CHECK_FALSE(bins->usable());
        CHECK(read(db, b, bins).from_recording == 0);
    }
    SECTION("another start than the stored acquiring event") {
        auto bins = std::make_shared<rec::TrialBins>(5.0);
        for (const auto& r : b.offered) {
            if (r.mono_ns > b.start_mono_ns && !bins->usable()) bins->start(b.start_mono_ns + 1);
            bins->add(r);
        }
        CHECK(bins->usable());
        CHECK(read(db, b, bins).from_recording == 0);
    }
    SECTION("another grid") {
        auto bins = std::make_shared<rec::TrialBins>(1.0);
        for (const auto& r : b.offered) {
            if (r.mono_ns > b.start_mono_ns && !bins->usable()) bins->start(b.start_mono_ns);
            bins->add(r);
        }
        CHECK(read(db, b, bins).from_recording == 0);
    }
    SECTION("never started") {
        auto bins = std::make_shared<rec::TrialBins>(5.0);
        for (const auto& r : b.offered) bins->add(r);
        CHECK(read(db, b, bins).from_recording == 0);
    }
}
