// Time (issue 17): trial timing is monotonic. A wall-clock step mid-trial (an NTP correction, a
// clock set by hand) moves only the UTC stamps: the same trial, run on the virtual clock once
// with two steps (-1 h, then +2 h) and once without, has the same stages, duration, steady
// window, samples and heat fluxes, and its stamps show exactly the steps.
#include <catch2/catch.hpp>

#include <cstdint>
#include <set>
#include <string>

#include "store/database_export.hpp"
#include "daemon_fixture.hpp"

using manikind::test::DaemonFixture;
using manikind::test::quick_plan;

namespace {

constexpr std::int64_t kHourNs = 3600LL * 1000000000LL;

struct Run {
    manikind::recorder::TrialRow trial;
    std::int64_t samples = 0;
    manikind::analysis::Trial exported;
    std::set<std::int64_t> utc_minus_mono_ns;  // one skin channel: each distinct wall-clock offset
};

Run run_trial(bool step_clock) {
    DaemonFixture fx;
    auto& d = fx.daemon();
    REQUIRE(d.start_campaign(quick_plan("clock")).empty());
    for (int s = 0; s < 4 * 3600 && d.status_json()["stage"] != "acquiring"; ++s) d.step_virtual(1.0);
    REQUIRE(d.status_json()["stage"] == "acquiring");
    for (int s = 0; s < 600; ++s) d.step_virtual(1.0);
    if (step_clock) d.step_wall_clock_virtual(-kHourNs);  // back an hour, mid-trial
    for (int s = 0; s < 600; ++s) d.step_virtual(1.0);
    if (step_clock) d.step_wall_clock_virtual(2 * kHourNs);  // then forward two
    d.run_virtual();

    auto& db = d.db();
    const auto campaign = db.find_campaign("clock");
    REQUIRE(campaign);
    const auto trials = db.trials(*campaign);
    REQUIRE(trials.size() == 1);
    Run r;
    r.trial = trials[0];
    r.samples = db.sample_count(r.trial.id);
    auto exported = manikind::campaign_from_database(db, "clock");
    REQUIRE(exported.trials.size() == 1);
    r.exported = exported.trials[0];
    for (const auto& ch : db.channels()) {
        if (ch.name != "z01.skin_temp_c") continue;
        for (const auto& s : db.samples(r.trial.id, ch.id)) r.utc_minus_mono_ns.insert(s.utc_ns - s.mono_ns);
    }
    return r;
}

}  // namespace

TEST_CASE("a wall-clock step mid-trial (NTP, a hand-set clock) moves only the UTC stamps: trial timing is monotonic",
          "[daemon][clock]") {
    const Run plain = run_trial(false);
    const Run stepped = run_trial(true);

    // Timing, on the monotonic clock: the same.
    CHECK(plain.trial.state == "done");
    CHECK(stepped.trial.state == plain.trial.state);
    CHECK(stepped.trial.reason == plain.trial.reason);
    REQUIRE(plain.trial.steady_from_mono_ns);
    CHECK(stepped.trial.steady_from_mono_ns == plain.trial.steady_from_mono_ns);
    CHECK(stepped.samples == plain.samples);
    REQUIRE(stepped.exported.data.rows() == plain.exported.data.rows());
    CHECK(stepped.exported.data.t_s == plain.exported.data.t_s);
    CHECK(stepped.exported.data.heat_flux_w_m2 == plain.exported.data.heat_flux_w_m2);
    CHECK(stepped.exported.data.skin_temp_c == plain.exported.data.skin_temp_c);

    // The stamps: one offset without steps; with them, the offset before, -1 h, then +1 h.
    REQUIRE(plain.utc_minus_mono_ns.size() == 1);
    const std::int64_t offset = *plain.utc_minus_mono_ns.begin();
    CHECK(stepped.utc_minus_mono_ns == std::set<std::int64_t>{offset - kHourNs, offset, offset + kHourNs});
    REQUIRE(plain.trial.started_utc_ns);
    REQUIRE(stepped.trial.started_utc_ns);
    CHECK(*stepped.trial.started_utc_ns == *plain.trial.started_utc_ns);
    CHECK(*stepped.trial.ended_utc_ns - *stepped.trial.started_utc_ns ==
          *plain.trial.ended_utc_ns - *plain.trial.started_utc_ns + kHourNs);
}
