#include "daemon/core/database_export.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <ctime>
#include <limits>
#include <map>

#include "analysis/zone_map.hpp"
#include "daemon/core/user_error.hpp"

namespace manikind {

namespace {

std::string iso_utc(std::int64_t utc_ns) {
    const std::time_t t = static_cast<std::time_t>(utc_ns / 1000000000);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

// Mean of good samples in each (t - period, t] bin relative to `t0_ns`; NaN where none.
std::vector<double> binned(const std::vector<recorder::SampleRow>& rows, std::int64_t t0_ns, std::size_t n, double period_s) {
    std::vector<double> sum(n, 0.0), count(n, 0.0);
    for (const auto& r : rows) {
        if (r.quality != 0 || !std::isfinite(r.value)) continue;
        const double t = static_cast<double>(r.mono_ns - t0_ns) * 1e-9;
        if (t < -period_s) continue;
        const auto i = static_cast<long>(std::ceil(t / period_s - 1e-9));
        if (i < 0 || static_cast<std::size_t>(i) >= n) continue;
        sum[static_cast<std::size_t>(i)] += r.value;
        count[static_cast<std::size_t>(i)] += 1.0;
    }
    std::vector<double> out(n, std::numeric_limits<double>::quiet_NaN());
    for (std::size_t i = 0; i < n; ++i)
        if (count[i] > 0) out[i] = sum[i] / count[i];
    return out;
}

std::vector<double> mean_of(const std::vector<std::vector<double>>& series, std::size_t n) {
    std::vector<double> out(n, std::numeric_limits<double>::quiet_NaN());
    for (std::size_t i = 0; i < n; ++i) {
        double s = 0;
        int k = 0;
        for (const auto& v : series)
            if (std::isfinite(v[i])) s += v[i], ++k;
        if (k) out[i] = s / k;
    }
    return out;
}

}  // namespace

analysis::Campaign campaign_from_database(recorder::Database& db, const std::string& name, double period_s) {
    const auto campaign_id = db.find_campaign(name);
    if (!campaign_id) throw UserError(fmt::format("{}: no campaign named '{}'", db.path().string(), name));
    analysis::Campaign c;
    c.name = name;
    c.zone_map = analysis::andi35_zone_map();
    c.instruments = analysis::default_instrument_specs();
    std::map<std::int64_t, nlohmann::json> conditions;
    std::map<std::int64_t, int> case_number;
    for (const auto& cs : db.cases(campaign_id.value())) {
        conditions[cs.id] = nlohmann::json::parse(cs.conditions_json, nullptr, false);
        case_number[cs.id] = conditions[cs.id].value("id", static_cast<int>(cs.position + 1));
    }
    std::map<std::string, std::int64_t> channel;  // "device/name" -> id
    for (const auto& ch : db.channels()) channel[ch.device_name + "/" + ch.name] = ch.id;
    auto series = [&](std::int64_t trial, const std::string& key, std::int64_t t0, std::size_t n) {
        const auto it = channel.find(key);
        if (it == channel.end()) return std::vector<double>(n, std::numeric_limits<double>::quiet_NaN());
        return binned(db.samples(trial, it->second), t0, n, period_s);
    };
    for (const auto& t : db.trials(campaign_id.value())) {
        if (t.state != "done") continue;
        std::optional<std::int64_t> start_ns, end_ns;
        for (const auto& e : db.events(t.id)) {
            if (e.kind == "stage" && e.message == "acquiring") start_ns = e.mono_ns;
            if (e.kind == "stage" && e.message == "stopping") end_ns = e.mono_ns;
        }
        if (!start_ns || !end_ns || *end_ns <= *start_ns) continue;
        const auto n = static_cast<std::size_t>(std::floor(static_cast<double>(*end_ns - *start_ns) * 1e-9 / period_s)) + 1;
        analysis::Trial trial;
        const nlohmann::json& cond = conditions[t.case_id];
        trial.info.case_id = case_number[t.case_id];
        trial.info.replicate = static_cast<int>(t.replicate);
        trial.info.id = fmt::format("c{:02d}-r{}", trial.info.case_id, t.replicate);
        trial.info.file = "trials/" + trial.info.id + ".csv";
        trial.info.skin_setpoint_c = cond.value("skin_setpoint_c", 35.0);
        trial.info.wettedness = cond.value("wet", false) ? 1.0 : 0.0;
        trial.info.chamber_setpoint_temp_c = cond.value("chamber_temp_c", 0.0);
        trial.info.chamber_setpoint_rh_pct = cond.value("chamber_rh_pct", 0.0);
        trial.info.started_utc = t.started_utc_ns ? iso_utc(*t.started_utc_ns) : "";
        auto& d = trial.data;
        for (std::size_t i = 0; i < n; ++i) d.t_s.push_back(static_cast<double>(i) * period_s);
        std::vector<std::vector<double>> temps, rhs, walls;
        for (int k = 1; k <= 8; ++k) {
            if (channel.count(fmt::format("datalogger/ee181_{}.air_temp_c", k)))
                temps.push_back(series(t.id, fmt::format("datalogger/ee181_{}.air_temp_c", k), *start_ns, n));
            if (channel.count(fmt::format("datalogger/ee181_{}.air_rh_pct", k)))
                rhs.push_back(series(t.id, fmt::format("datalogger/ee181_{}.air_rh_pct", k), *start_ns, n));
            if (channel.count(fmt::format("datalogger/wall_tc_{}.wall_temp_c", k)))
                walls.push_back(series(t.id, fmt::format("datalogger/wall_tc_{}.wall_temp_c", k), *start_ns, n));
        }
        d.air_temp_c = mean_of(temps, n);
        d.air_rh_pct = mean_of(rhs, n);
        if (!walls.empty()) d.wall_temp_c = mean_of(walls, n);
        if (channel.count("windsonic/air_speed_m_s")) d.air_speed_m_s = series(t.id, "windsonic/air_speed_m_s", *start_ns, n);
        for (const auto& z : c.zone_map.zones) {
            d.skin_temp_c.push_back(series(t.id, fmt::format("manikin/z{:02d}.skin_temp_c", z.zone), *start_ns, n));
            d.heat_flux_w_m2.push_back(series(t.id, fmt::format("manikin/z{:02d}.heat_flux_w_m2", z.zone), *start_ns, n));
        }
        c.trials.push_back(std::move(trial));
    }
    if (c.trials.empty()) throw UserError(fmt::format("campaign '{}' has no finished trial yet", name));
    return c;
}

void export_campaign(recorder::Database& db, const std::string& name, const std::filesystem::path& folder) {
    analysis::write_campaign(folder, campaign_from_database(db, name));
}

}  // namespace manikind
