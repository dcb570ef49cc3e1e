// Issue 34: the manikin under the thermoregulation model's control, end to end on the simulated
// lab and the virtual clock: the daemon drives the world's manikin zone by zone over the CAN bus
// from the model, the world's physics (humidity buoyancy included) answers with measured losses,
// the model is recorded as device "model", and the result is compared with the same model run
// offline (physics/thermoreg's simulate(), the independent batch run) in the recorded conditions.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <map>

#include "analysis/input_error.hpp"
#include "analysis/physio.hpp"
#include "daemon/campaign_plan.hpp"
#include "daemon_fixture.hpp"
#include "physics/thermoreg/stolwijk.hpp"
#include "store/database_export.hpp"

namespace tr = manikind::physics::thermoreg;
namespace ph = manikind::analysis::physio;

namespace {
manikind::CampaignPlan physiological_plan(int case_id) {
    auto plan = manikind::load_campaign_plan(MANIKIND_CONFIG_DIR "/campaign-physiological.toml");
    plan.cases.erase(std::remove_if(plan.cases.begin(), plan.cases.end(), [&](const auto& c) { return c.id != case_id; }),
                     plan.cases.end());
    REQUIRE(plan.cases.size() == 1);
    plan.replicates = 1;  // one run proves the loop; the template runs three for physio's Type A
    return plan;
}

// Runs the plan's one trial on the virtual clock: it must end done; `fell_back` says whether the
// trial must carry the model-fallback flag.
manikind::recorder::Database& run_one_trial(manikind::test::DaemonFixture& f, const manikind::CampaignPlan& plan, bool fell_back) {
    const auto trial = f.run_one_done_trial(plan);
    CHECK(((trial.quality_flags & manikind::flag_model_fallback) != 0) == fell_back);
    return f.daemon().db();
}

manikind::recorder::Database& run_without_fallback(manikind::test::DaemonFixture& f, const manikind::CampaignPlan& plan) {
    return run_one_trial(f, plan, false);
}

// The mean of a recorded analysis column over the rows from t_from_s on.
double mean_from(const std::vector<double>& t_s, const std::vector<double>& v, double t_from_s) {
    double sum = 0.0;
    int n = 0;
    for (std::size_t i = 0; i < v.size(); ++i)
        if (t_s[i] >= t_from_s && std::isfinite(v[i])) sum += v[i], ++n;
    return n ? sum / n : std::nan("");
}

// Largest departure from the centred 10-min running mean, over points with t in [lo, hi).
double wobble(const std::vector<ph::Point>& p, double (*value)(const ph::Point&), double lo_s, double hi_s) {
    double worst = 0.0;
    for (std::size_t i = 0; i < p.size(); ++i) {
        if (p[i].t_s < lo_s || p[i].t_s >= hi_s) continue;
        double sum = 0.0;
        int n = 0;
        for (const auto& q : p)
            if (std::abs(q.t_s - p[i].t_s) <= 300.0) sum += value(q), ++n;
        if (p[i].t_s - 300.0 < p.front().t_s || p[i].t_s + 300.0 > p.back().t_s) continue;
        worst = std::max(worst, std::abs(value(p[i]) - sum / n));
    }
    return worst;
}
}  // namespace

TEST_CASE("physiological trial on the simulated lab: 2 h at 41 C, 20 % RH reproduce the offline coupled model within "
          "0.2 C core and 0.3 C mean skin, and end closer to it than to temperature-only convection",
          "[daemon][physiological][proof]") {
    manikind::test::DaemonFixture f;
    const auto plan = physiological_plan(1);
    auto& db = run_without_fallback(f, plan);

    const auto campaign = manikind::campaign_from_database(db, plan.name);
    // Recorded like any device: the export's columns are model.<channel>.
    std::map<std::string, bool> columns;
    for (const auto& c : campaign.channels) columns[c.column()] = true;
    for (const char* c : {"model.core_temp_c", "model.mean_skin_temp_c", "model.trunk.skin_temp_c", "model.hands.core_temp_c",
                          "model.feet.sweat_rate_g_m2_h", "model.heat_loss_w", "model.metabolic_w", "model.legs.heat_loss_w"})
        CHECK(columns.count(c) == 1);
    const auto r = ph::compute(campaign);
    REQUIRE(r.trials.size() == 1);
    const auto& t = r.trials[0];
    CHECK(t.replay_max_abs_diff_c < 1e-9);  // the record holds everything the model was given
    // A damaged record is refused by name, never replayed into nonsense or a crash.
    auto damaged = [&](const std::string& channel, double value) {
        auto c = campaign;
        for (std::size_t i = 0; i < c.channels.size(); ++i)
            if (c.channels[i].column() == channel) {
                auto& v = c.trials[0].data.channel_values[i];
                for (std::size_t row = 0; row < v.size(); ++row)
                    if (c.trials[0].data.channel_quality[i][row] != manikind::analysis::kNoSample) {
                        v[row] = value;
                        break;
                    }
            }
        try {
            (void)ph::compute(c);
        } catch (const manikind::analysis::InputError& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    CHECK_THAT(damaged("model.air_rh_pct", 150.0), Catch::Contains("cannot be replayed") && Catch::Contains("humidity"));
    CHECK_THAT(damaged("model.time_s", -5.0), Catch::Contains("model.time_s"));
    CHECK_THAT(damaged("model.metabolic_met", 50.0), Catch::Contains("metabolic"));
    CHECK_THAT(damaged("model.trunk.heat_loss_w", 1e9), Catch::Contains("cannot be replayed"));
    CHECK(t.coupling_period_s == Approx(f.daemon().config().physiological.coupling_period_s));
    REQUIRE(t.points.size() >= 300);
    CHECK(t.points.back().t_s == Approx(7200.0));

    // The offline model in the recorded conditions: the enclosure's air, RH and walls (its MRT)
    // while the model ran, the manikin bare (clo 0).
    const auto& data = campaign.trials[0].data;
    const double model_start_s = data.t_s.back() - 7200.0;
    tr::Exposure e;
    e.air_temp_c = mean_from(data.t_s, data.air_temp_c, model_start_s);
    e.rh_pct = mean_from(data.t_s, data.air_rh_pct, model_start_s);
    e.mrt_c = mean_from(data.t_s, data.wall_temp_c, model_start_s);
    CHECK(e.mrt_c == Approx(40.6).margin(0.4));  // walls 0.4 °C below the air (Text S3.3)
    tr::ModelOptions coupled_o, dt_o;
    coupled_o.clo = dt_o.clo = 0.0;
    dt_o.convection = tr::ConvectionModel::dt_only;
    const auto coupled = tr::simulate(e, coupled_o), dt_only = tr::simulate(e, dt_o);
    double worst_core = 0.0, worst_skin = 0.0;
    int compared = 0;
    for (const auto& p : t.points) {
        const auto minute = static_cast<std::size_t>(std::llround(p.t_s / 60.0));
        if (std::abs(p.t_s - 60.0 * static_cast<double>(minute)) > 1e-6 || minute >= coupled.series.size()) continue;
        worst_core = std::max(worst_core, std::abs(p.core_temp_c - coupled.series[minute].core_temp_c));
        worst_skin = std::max(worst_skin, std::abs(p.mean_skin_temp_c - coupled.series[minute].mean_skin_temp_c));
        ++compared;
    }
    INFO("worst core " << worst_core << " °C, worst mean skin " << worst_skin << " °C over " << compared << " minutes");
    CHECK(compared >= 119);
    CHECK(worst_core <= 0.2);
    CHECK(worst_skin <= 0.3);
    const double end_skin = t.points.back().mean_skin_temp_c;
    INFO("end skin: loop " << end_skin << ", coupled " << coupled.final.mean_skin_temp_c << ", dt-only "
                           << dt_only.final.mean_skin_temp_c);
    CHECK(std::abs(end_skin - coupled.final.mean_skin_temp_c) < std::abs(end_skin - dt_only.final.mean_skin_temp_c));
    // The manikin followed: its zones' mean skin at the end is the model's.
    double zone_mean = 0.0, area = 0.0;
    for (std::size_t z = 0; z < campaign.zone_map.size(); ++z) {
        zone_mean += data.skin_temp_c[z].back() * campaign.zone_map.zones[z].area_m2;
        area += campaign.zone_map.zones[z].area_m2;
    }
    CHECK(zone_mean / area == Approx(end_skin).margin(0.3));
    // Stability in the heat: after the first half hour the model's mean skin stays within 0.1 °C,
    // its core within 0.01 °C, of their 10-min running means (docs/thermoregulation.md).
    CHECK(wobble(t.points, [](const ph::Point& p) { return p.mean_skin_temp_c; }, 1800, 7200) < 0.1);
    CHECK(wobble(t.points, [](const ph::Point& p) { return p.core_temp_c; }, 1800, 7200) < 0.01);

    // The energy balance (issue 63): what the loop took out of the heaters' power as the shell's
    // storage, summed over the model's steps, is the heat the shell holds for its rise in skin
    // temperature, C sum A_z dT_z, from the recorder's own zone temperatures. 9 kJ here: fed to
    // the model as body heat loss before the correction.
    std::map<std::string, std::size_t> column;
    for (std::size_t i = 0; i < campaign.channels.size(); ++i) column[campaign.channels[i].column()] = i;
    REQUIRE(column.count("model.shell_storage_w") == 1);
    const auto& storage = data.channel_values[column.at("model.shell_storage_w")];
    const auto& quality = data.channel_quality[column.at("model.shell_storage_w")];
    const double period_s = f.daemon().config().physiological.coupling_period_s;
    double stored_j = 0.0;
    std::size_t first = data.rows(), last = 0;
    for (std::size_t row = 0; row < data.rows(); ++row)
        if (quality[row] != manikind::analysis::kNoSample) {
            stored_j += storage[row] * period_s;
            first = std::min(first, row), last = row;
        }
    REQUIRE(first < last);
    const double c_j_m2k = f.daemon().config().physiological.shell_heat_capacity_j_m2k;
    double held_j = 0.0;
    for (std::size_t z = 0; z < campaign.zone_map.size(); ++z)  // the skin one period before the first step to the last
        held_j += c_j_m2k * campaign.zone_map.zones[z].area_m2 *
                  (data.skin_temp_c[z][last] - data.skin_temp_c[z][first - static_cast<std::size_t>(period_s / 5.0)]);
    INFO("shell storage fed out " << stored_j << " J, held by the shell " << held_j << " J");
    CHECK(std::abs(held_j) > 3000.0);
    CHECK(stored_j == Approx(held_j).epsilon(0.05).margin(200.0));
}

TEST_CASE("physiological trial on the simulated lab: a step from 41 C to 25 C mid-trial is followed without "
          "oscillation beyond the stated bound, and the model stays within 0.3 C of itself run alone in the same "
          "recorded conditions", "[daemon][physiological][proof]") {
    manikind::test::DaemonFixture f;
    const auto plan = physiological_plan(2);
    auto& db = run_without_fallback(f, plan);
    const auto campaign = manikind::campaign_from_database(db, plan.name);
    // The chamber followed the protocol: the enclosure ends near 25 °C.
    const auto& data = campaign.trials[0].data;
    CHECK(mean_from(data.t_s, data.air_temp_c, data.t_s.back() - 600.0) == Approx(25.0).margin(1.0));
    const auto r = ph::compute(campaign);
    REQUIRE(r.trials.size() == 1);
    const auto& p = r.trials[0].points;
    double worst_skin = 0.0;
    for (const auto& q : p) worst_skin = std::max(worst_skin, std::abs(q.mean_skin_temp_c - q.alone_coupled_skin_c));
    // In the heat the measured exchange holds the skin up to ~0.3 °C above the model alone (the
    // first test); in the cool phase there is no humidity plume and the two meet.
    CHECK(std::abs(p.back().mean_skin_temp_c - p.back().alone_coupled_skin_c) < 0.15);
    CHECK(worst_skin < 0.4);
    // The stated bound after the step (docs/thermoregulation.md): within 0.15 °C (mean skin) and
    // 0.02 °C (core) of the 10-min running mean, which the step itself moves by ~0.05 °C/min.
    CHECK(wobble(p, [](const ph::Point& q) { return q.mean_skin_temp_c; }, 3600, 7200) < 0.15);
    CHECK(wobble(p, [](const ph::Point& q) { return q.core_temp_c; }, 3600, 7200) < 0.02);
    // The commanded setpoints (recorded as model.zNN.skin_setpoint_c) never moved faster than the
    // configured rate, the step included.
    const double rate_c_s = f.daemon().config().physiological.max_setpoint_rate_c_min / 60.0;
    std::size_t setpoint_channels = 0;
    double fastest_c_s = 0.0;
    for (std::size_t c = 0; c < campaign.channels.size(); ++c) {
        if (campaign.channels[c].device != "model" || !campaign.channels[c].name.ends_with(".skin_setpoint_c")) continue;
        ++setpoint_channels;
        double last_t = -1.0, last_v = 0.0;
        for (std::size_t i = 0; i < data.rows(); ++i) {
            if (data.channel_quality[c][i] == manikind::analysis::kNoSample) continue;
            if (last_t >= 0.0) fastest_c_s = std::max(fastest_c_s, std::abs(data.channel_values[c][i] - last_v) / (data.t_s[i] - last_t));
            last_t = data.t_s[i];
            last_v = data.channel_values[c][i];
        }
    }
    CHECK(setpoint_channels == campaign.zone_map.size());
    INFO("fastest setpoint change: " << fastest_c_s * 60.0 << " °C/min");
    CHECK(fastest_c_s <= rate_c_s * 1.3);  // a 5-s bin's timing around the 20-s commands
    CHECK(fastest_c_s >= rate_c_s * 0.5);  // the step did drive the setpoints at the limit
}

TEST_CASE("physiological trial on the simulated lab: a zone whose heater fails mid-trial is flagged by the manikin, the "
          "loop falls back to constant skin temperature with an alarm naming it, and the trial is flagged",
          "[daemon][physiological][proof]") {
    manikind::test::DaemonFixture f([](manikind::config::Config& c) {
        c.simulation.faults = {"manikin:heater_fail=12@5400"};  // during the model's first hour
    });
    auto plan = physiological_plan(1);
    plan.cases[0].model->duration_s = 3600.0;
    auto& db = run_one_trial(f, plan, true);
    bool alarmed = false;
    for (const auto& e : db.events(std::nullopt))
        alarmed = alarmed || (e.kind == "physiological" && e.severity == "error" &&
                              e.message.find("zone 12") != std::string::npos &&
                              e.message.find("constant skin temperature") != std::string::npos);
    CHECK(alarmed);
    const auto r = ph::compute(manikind::campaign_from_database(db, plan.name));
    REQUIRE(r.trials.size() == 1);
    CHECK(r.trials[0].fell_back);
    // The campaign's outcome is not ok after a fallback (issue 64): --exit-when-done and
    // `campaign run --wait` exit 6, not 0.
    const auto outcome = f.daemon().campaign_outcome_json(plan.name);
    CHECK(outcome["model_fallbacks"] == 1);
    CHECK(outcome["ok"] == false);
}

TEST_CASE("physiological trials on the simulated lab: the band physio gives from three runs of a case holds a fourth "
          "run's trajectory, and the model alone's comparison carries the probes' uncertainty",
          "[daemon][physiological][proof]") {
    // Issue 63: one run's band was Type B alone and a second run of the same hour fell outside it
    // at most steps. Four runs of Fig. 4's case on the virtual clock; the band from the first three.
    manikind::test::DaemonFixture f;
    auto plan = physiological_plan(1);
    plan.replicates = 4;
    REQUIRE(f.daemon().start_campaign(plan).empty());
    f.daemon().run_virtual();
    const auto campaign = manikind::campaign_from_database(f.daemon().db(), plan.name);
    REQUIRE(campaign.trials.size() == 4);
    auto three = campaign;
    three.trials.erase(std::remove_if(three.trials.begin(), three.trials.end(), [](const auto& t) { return t.info.replicate == 4; }),
                       three.trials.end());
    auto fourth = campaign;
    fourth.trials.erase(std::remove_if(fourth.trials.begin(), fourth.trials.end(), [](const auto& t) { return t.info.replicate != 4; }),
                        fourth.trials.end());
    ph::Options o;
    o.draws = 20;
    const auto band = ph::compute(three, o), further = ph::compute(fourth, o);
    REQUIRE(band.cases.size() == 1);
    REQUIRE(further.trials.size() == 1);
    const auto& c = band.cases[0];
    CHECK(c.replicates == 3);
    const auto& run4 = further.trials[0].points;
    REQUIRE(run4.size() == c.points.size());
    int steps = 0, skin_in = 0, core_in = 0;
    double widest_skin = 0.0;
    for (std::size_t k = 0; k < run4.size(); ++k) {
        const auto& p = c.points[k];
        REQUIRE(run4[k].t_s == Approx(p.t_s));
        REQUIRE(std::isfinite(p.skin_repro_u95_c));
        ++steps;
        skin_in += std::abs(run4[k].mean_skin_temp_c - p.mean_skin_temp_c) <= p.skin_repro_u95_c ? 1 : 0;
        core_in += std::abs(run4[k].core_temp_c - p.core_temp_c) <= p.core_repro_u95_c ? 1 : 0;
        widest_skin = std::max(widest_skin, p.skin_repro_u95_c);
    }
    // One trajectory is one draw of a correlated path: its share of steps inside the pointwise 95 %
    // band scatters widely about 95 % (the rate itself is proven on 200 sets in
    // tests/analysis/test_physio.cpp). Measured 2026-11-30: skin 319, core 344 of 360.
    INFO("the fourth run inside the band at " << skin_in << " (skin) and " << core_in << " (core) of " << steps
                                              << " steps; the widest skin band ± " << widest_skin << " °C");
    CHECK(skin_in >= steps * 8 / 10);
    CHECK(core_in >= steps * 8 / 10);
    // The band is the runs' spread, not Type B's: wider than one run's instrument band somewhere.
    CHECK(widest_skin > 0.05);
    // The model alone's band is the probes': its comparison is a verdict with the band, per case.
    CHECK(c.agreement.points == static_cast<int>(c.points.size()));
    CHECK(c.points.back().alone_skin_u95_c > 0.0);
    CHECK(c.points.back().diff_skin_u95_c > 0.0);
}
