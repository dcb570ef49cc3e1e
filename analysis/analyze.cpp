#include "analysis/analyze.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <future>
#include <limits>
#include <ostream>
#include <set>
#include <stdexcept>

#include <fmt/core.h>

namespace manikind::analysis {

namespace {

// Time-mean of the finite samples from index `first` on ("zonal-time average", Text S3).
// Samples are equally spaced in a recording, so the sample mean is the time mean.
double window_mean(const std::vector<double>& values, std::size_t first) {
    double sum = 0.0;
    std::size_t n = 0;
    for (std::size_t i = first; i < values.size(); ++i) {
        if (!std::isfinite(values[i])) continue;
        sum += values[i];
        ++n;
    }
    return n ? sum / static_cast<double>(n) : kNaN;
}

// Region or whole body from the zones `idx`: per-trial area-weighted means give Type A (so
// the replicate scatter carries every correlation between zones); zone Type B limits
// propagate through the weights as set by `correlation`. Budget lines group the Type B
// part by `group_of(zone index)`.
template <typename GroupOf>
AreaResult area_result(const std::string& name, const std::vector<std::size_t>& idx, const ZoneMap& map,
                       const std::vector<const TrialResult*>& trials, const std::vector<ZoneResult>& zones,
                       const AnalysisOptions& o, GroupOf group_of) {
    AreaResult a;
    a.name = name;
    for (auto z : idx) a.area_m2 += map.zones[z].area_m2;
    std::vector<double> per_trial;
    for (const auto* t : trials) {
        double q = 0.0;
        for (auto z : idx) q += map.zones[z].area_m2 / a.area_m2 * t->zone_q_w_m2[z];
        per_trial.push_back(q);
    }
    std::vector<std::string> groups;
    std::vector<double> group_linear, group_squares;
    double linear = 0.0, squares = 0.0;
    for (auto z : idx) {
        const double c = map.zones[z].area_m2 / a.area_m2 * zones[z].q.u_b;
        linear += c;
        squares += c * c;
        const std::string g = group_of(z);
        auto it = std::find(groups.begin(), groups.end(), g);
        if (it == groups.end()) {
            groups.push_back(g);
            group_linear.push_back(0.0);
            group_squares.push_back(0.0);
            it = groups.end() - 1;
        }
        const auto gi = static_cast<std::size_t>(it - groups.begin());
        group_linear[gi] += c;
        group_squares[gi] += c * c;
    }
    const bool correlated = o.type_b_correlation == TypeBCorrelation::correlated;
    const double u_b = correlated ? linear : std::sqrt(squares);
    const int n = static_cast<int>(per_trial.size());
    // Correlated or not, every zone's u_B carries the same relative uncertainty, so the
    // region's u_B has the same Type B dof (GUM G.4.2).
    a.q = combine(mean(per_trial), type_a_of_mean(per_trial), n, u_b, o.coverage_options());
    const double u_c2 = a.q.u_c * a.q.u_c;
    auto share = [&](double part2) { return u_c2 > 0.0 ? part2 / u_c2 : 0.0; };
    if (a.q.type_a_estimable)
        a.budget.push_back({fmt::format("Type A: replicate scatter (n = {})", n), 'A', a.q.u_a, n - 1.0,
                            share(a.q.u_a * a.q.u_a), ""});
    else  // absent, not zero: the share stays 0 and u is NaN (null in JSON)
        a.budget.push_back({fmt::format("Type A: not estimable (n = {})", n), 'A', a.q.u_a, kNaN, 0.0, ""});
    for (std::size_t g = 0; g < groups.size(); ++g) {
        // Correlated parts add linearly: u_B² = sum_g c_g u_B, so c_g u_B is group g's share.
        const double c_g = correlated ? group_linear[g] : std::sqrt(group_squares[g]);
        a.budget.push_back({"Type B: heat-flux sensors, " + groups[g], 'B', c_g, a.q.nu_b,
                            share(correlated ? c_g * u_b : c_g * c_g), groups[g]});
    }
    return a;
}

ConditionEstimate condition(const std::string& channel, const std::vector<const TrialResult*>& trials,
                            double TrialResult::*field, const Campaign& campaign, const AnalysisOptions& o) {
    std::vector<double> values;
    for (const auto* t : trials)
        if (std::isfinite(t->*field)) values.push_back(t->*field);
    ConditionEstimate c;
    c.channel = channel;
    if (values.empty()) {
        c.e.value = kNaN;
        return c;
    }
    const auto spec = campaign.instruments.count(channel) ? campaign.instruments.at(channel) : InstrumentSpec{};
    const double m = mean(values);
    c.e = combine(m, type_a_of_mean(values), static_cast<int>(values.size()), spec.standard_uncertainty(m),
                  o.coverage_options());
    return c;
}

// consume(i, produce(i)) for i = 0 .. n - 1 in order, each produce(i) on a thread of its own,
// up to `ahead` of them running while consume works: at most ahead + 1 results alive. An
// exception from produce(i) reaches the caller at i's turn, after every earlier consume.
template <typename Produce, typename Consume>
void in_order_ahead(std::size_t n, std::size_t ahead, const Produce& produce, const Consume& consume) {
    using Result = decltype(produce(std::size_t{0}));
    std::deque<std::future<Result>> running;
    std::size_t launched = 0;
    const auto launch = [&] {
        while (launched < n && running.size() < ahead) running.push_back(std::async(std::launch::async, produce, launched++));
    };
    launch();
    for (std::size_t i = 0; i < n; ++i) {
        Result result = running.front().get();
        running.pop_front();
        launch();
        consume(i, std::move(result));
    }
}

}  // namespace

TrialResult summarize_trial(const Trial& trial, const ZoneMap& map, const AnalysisOptions& o) {
    const TrialData& d = trial.data;
    TrialResult r;
    r.id = trial.info.id;
    r.replicate = trial.info.replicate;
    r.rows = d.rows();
    r.steady = detect_steady_state(d, map, o.steady);
    r.whole_body_q_w_m2 = kNaN;
    r.air_temp_c = r.air_rh_pct = r.air_speed_m_s = r.wall_temp_c = r.mean_skin_temp_c = kNaN;
    if (d.rows() == 0) {
        r.exclusion_reason = "empty trial: no samples";
        return r;
    }
    if (trial.info.control == "physiological") {
        r.exclusion_reason = "physiological trial (skin and sweat decided by the thermoregulation model): no steady state "
                             "by design; its results are trajectories: manikin physio";
        return r;
    }
    const double start_s = r.steady.window_start_s - 1e-9 * std::max(1.0, std::fabs(r.steady.window_start_s));
    const auto first = static_cast<std::size_t>(std::lower_bound(d.t_s.begin(), d.t_s.end(), start_s) - d.t_s.begin());
    std::string missing;
    const double total_area_m2 = map.total_area_m2();
    double whole_body = 0.0;
    double skin = 0.0;
    for (std::size_t z = 0; z < map.size(); ++z) {
        r.zone_q_w_m2.push_back(window_mean(d.heat_flux_w_m2[z], first));
        r.zone_skin_temp_c.push_back(window_mean(d.skin_temp_c[z], first));
        if ((std::isnan(r.zone_q_w_m2.back()) || std::isnan(r.zone_skin_temp_c.back())) && missing.empty())
            missing = fmt::format("zone {:02} ({}) has no samples in the window", map.zones[z].zone, map.zones[z].name);
        const double w = map.zones[z].area_m2 / total_area_m2;
        whole_body += w * r.zone_q_w_m2.back();  // segmental area weighting (Text S3)
        skin += w * r.zone_skin_temp_c.back();
    }
    r.whole_body_q_w_m2 = whole_body;
    r.mean_skin_temp_c = skin;
    r.air_temp_c = window_mean(d.air_temp_c, first);
    r.air_rh_pct = window_mean(d.air_rh_pct, first);
    if (!d.air_speed_m_s.empty()) r.air_speed_m_s = window_mean(d.air_speed_m_s, first);
    if (!d.wall_temp_c.empty()) r.wall_temp_c = window_mean(d.wall_temp_c, first);

    const bool partial = r.steady.window_end_s - d.t_s.front() < o.steady.window_s;
    if (!missing.empty()) r.exclusion_reason = "unusable: " + missing;
    else if (partial) r.exclusion_reason = r.steady.reason;  // never averaged, even with include_unsteady
    else if (std::isnan(r.air_temp_c) || std::isnan(r.air_rh_pct))
        r.exclusion_reason = "unusable: no air temperature or humidity sample in the window";
    else if (!r.steady.steady && !o.include_unsteady) r.exclusion_reason = "not steady: " + r.steady.reason;
    r.included = r.exclusion_reason.empty();
    return r;
}

const char* to_string(TypeBCorrelation c) {
    return c == TypeBCorrelation::correlated ? "correlated" : "uncorrelated";
}

CoverageOptions AnalysisOptions::coverage_options() const {
    CoverageOptions c;
    c.coverage = coverage;
    c.type_b_dof = type_b_dof(type_b_relative_uncertainty);  // GUM G.4.2
    c.confidence = confidence;
    return c;
}

CampaignResult analyze_campaign(const Campaign& campaign, const AnalysisOptions& o) {
    std::vector<TrialResult> results;
    results.reserve(campaign.trials.size());
    for (const auto& t : campaign.trials) results.push_back(summarize_trial(t, campaign.zone_map, o));
    return aggregate_trials(campaign, results, o);
}

CampaignResult analyze_campaign_streaming(const std::filesystem::path& folder, const ReadOptions& read,
                                          const AnalysisOptions& o) {
    const Campaign metadata = read_campaign_metadata(folder, read);
    const std::size_t n = metadata.trials.size();
    std::vector<TrialResult> results;
    results.reserve(n);
    // The parse is most of the work, so two trials are parsed at once, each on its own thread,
    // while the one before them is summarised here: at most three trials are in memory. A bad
    // file still fails at its own trial, after the trials before it, as one thread would (the
    // error waits in its future until its turn).
    in_order_ahead(
        n, 2, [&](std::size_t i) { return read_trial_data(folder, metadata, metadata.trials[i].info); },
        [&](std::size_t i, TrialData data) {
            // Scoped: the samples are freed before a later trial is read into their place.
            const Trial trial{metadata.trials[i].info, std::move(data)};
            results.push_back(summarize_trial(trial, metadata.zone_map, o));
        });
    return aggregate_trials(metadata, results, o);
}

CampaignResult aggregate_trials(const Campaign& campaign, const std::vector<TrialResult>& results,
                                const AnalysisOptions& o) {
    if (results.size() != campaign.trials.size())
        throw std::invalid_argument(fmt::format("aggregate_trials: {} results for {} trials", results.size(),
                                                campaign.trials.size()));
    CampaignResult out;
    out.campaign = campaign.name;
    out.options = o;
    out.warnings = campaign.warnings;
    const ZoneMap& map = campaign.zone_map;
    const InstrumentSpec flux_spec = campaign.instruments.count("heat_flux_w_m2")
                                         ? campaign.instruments.at("heat_flux_w_m2")
                                         : default_instrument_specs().at("heat_flux_w_m2");

    // Indices into campaign.trials and results, per case.
    std::map<int, std::vector<std::size_t>> by_case;
    for (std::size_t i = 0; i < campaign.trials.size(); ++i) by_case[campaign.trials[i].info.case_id].push_back(i);

    for (auto& [case_id, trials] : by_case) {
        std::stable_sort(trials.begin(), trials.end(), [&](std::size_t a, std::size_t b) {
            return campaign.trials[a].info.replicate < campaign.trials[b].info.replicate;
        });
        CaseResult c;
        c.case_id = case_id;
        std::vector<const TrialResult*> used;
        c.trials.reserve(trials.size());
        for (const auto i : trials) c.trials.push_back(results[i]);
        std::set<double> wettedness, setpoints;
        for (std::size_t i = 0; i < trials.size(); ++i) {
            const auto& tr = c.trials[i];
            const TrialInfo& info = campaign.trials[trials[i]].info;
            if (!tr.included) {
                out.warnings.push_back(fmt::format("case {}: trial '{}' excluded: {}", case_id, tr.id, tr.exclusion_reason));
                continue;
            }
            if (!tr.steady.steady)
                c.warnings.push_back(fmt::format("trial '{}' is included although not steady ({})", tr.id, tr.steady.reason));
            used.push_back(&tr);
            if (info.wettedness) wettedness.insert(*info.wettedness);
            if (info.skin_setpoint_c) setpoints.insert(*info.skin_setpoint_c);
            if (c.local.empty()) c.local = info.local;  // one room per case (the plan states it per case)
        }
        c.n_replicates = static_cast<int>(used.size());
        if (used.empty()) {
            out.warnings.push_back(fmt::format("case {}: no usable trial, no results", case_id));
            out.unanalysed_cases.push_back(std::move(c));
            continue;
        }
        c.type_a_estimable = used.size() >= 2;
        if (!c.type_a_estimable) {
            c.warnings.push_back("one usable replicate: Type A is not estimable (u_A absent, not 0), U covers Type B only");
            if (o.coverage == Coverage::replicates_t)
                c.warnings.push_back("the paper's k = t(n - 1) needs at least 2 replicates: k from Type B alone");
        }
        if (wettedness.size() > 1) c.warnings.push_back("replicates disagree on wettedness");
        if (setpoints.size() > 1) c.warnings.push_back("replicates disagree on the skin setpoint");
        if (!wettedness.empty()) c.wettedness = *wettedness.begin();
        if (!setpoints.empty()) c.skin_setpoint_c = *setpoints.begin();

        for (std::size_t z = 0; z < map.size(); ++z) {
            std::vector<double> values, skin;
            for (const auto* t : used) {
                values.push_back(t->zone_q_w_m2[z]);
                skin.push_back(t->zone_skin_temp_c[z]);
            }
            ZoneResult zr;
            zr.zone = map.zones[z].zone;
            zr.name = map.zones[z].name;
            zr.region = map.zones[z].region;
            zr.area_m2 = map.zones[z].area_m2;
            zr.skin_temp_c = mean(skin);
            const double m = mean(values);
            // Type B of a zone mean: the sensor's limit at the mean reading. Neither time
            // averaging nor replication shrinks it: a calibration error repeats in every
            // sample and every replicate (fully correlated), unlike noise.
            zr.q = combine(m, type_a_of_mean(values), c.n_replicates, flux_spec.standard_uncertainty(m),
                           o.coverage_options());
            c.zones.push_back(std::move(zr));
        }
        std::vector<std::size_t> all(map.size());
        for (std::size_t z = 0; z < map.size(); ++z) all[z] = z;
        c.whole_body = area_result("whole_body", all, map, used, c.zones, o,
                                   [&](std::size_t z) { return map.zones[z].region; });
        for (const auto& region : map.regions())
            c.regions.push_back(area_result(region, map.zones_in(region), map, used, c.zones, o,
                                            [&](std::size_t z) { return map.zones[z].name; }));
        c.conditions.push_back(condition("air_temp_c", used, &TrialResult::air_temp_c, campaign, o));
        c.conditions.push_back(condition("air_rh_pct", used, &TrialResult::air_rh_pct, campaign, o));
        c.conditions.push_back(condition("skin_temp_c", used, &TrialResult::mean_skin_temp_c, campaign, o));
        auto speed = condition("air_speed_m_s", used, &TrialResult::air_speed_m_s, campaign, o);
        if (std::isfinite(speed.e.value)) c.conditions.push_back(speed);
        auto wall = condition("wall_temp_c", used, &TrialResult::wall_temp_c, campaign, o);
        if (std::isfinite(wall.e.value)) c.conditions.push_back(wall);
        out.cases.push_back(std::move(c));
    }
    return out;
}

// --- output -----------------------------------------------------------------------------

namespace {

using nlohmann::json;

json number_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json estimate_json(const Estimate& e) {
    return {{"q_w_m2", e.value}, {"u_a", number_or_null(e.u_a)}, {"type_a_estimable", e.type_a_estimable},
            {"u_b", e.u_b}, {"nu_b", number_or_null(e.nu_b)}, {"u_c", e.u_c}, {"k", e.k}, {"U", e.U},
            {"nu_eff", number_or_null(e.nu_eff)}, {"k_dof", number_or_null(e.k_dof)},
            {"ci_low_w_m2", e.value - e.U}, {"ci_high_w_m2", e.value + e.U}};
}

json budget_json(const std::vector<BudgetLine>& budget) {
    json out = json::array();
    for (const auto& b : budget)
        out.push_back({{"source", b.source}, {"type", std::string(1, b.type)}, {"u_w_m2", number_or_null(b.u_w_m2)},
                       {"dof", number_or_null(b.dof)}, {"share", b.share}, {"part", b.part}});
    return out;
}

json area_json(const AreaResult& a, bool region) {
    json j = estimate_json(a.q);
    if (region) j["region"] = a.name;
    j["area_m2"] = a.area_m2;
    j["budget"] = budget_json(a.budget);
    return j;
}

json skin_drift_json(const SteadyStateResult& s) {
    json zones = json::array();
    for (const auto& z : s.zone_skin)
        zones.push_back({{"zone", z.zone}, {"samples", z.samples}, {"range_c", number_or_null(z.range_c)},
                         {"drift_c_per_30min", number_or_null(z.drift_c_per_30min)},
                         {"u_drift_c_per_30min", number_or_null(z.u_drift_c_per_30min)},
                         {"residual_sd_c", number_or_null(z.residual_sd_c)},
                         {"lag1_autocorrelation", number_or_null(z.lag1_autocorrelation)}});
    return {{"max_drift_c_per_30min", s.max_skin_drift_c_per_30min},
            {"u_max_drift_c_per_30min", number_or_null(s.u_max_skin_drift_c_per_30min)},
            {"worst_zone", s.worst_skin_drift_zone},
            {"zones", zones}};
}

json trial_json(const TrialResult& t) {
    const auto& s = t.steady;
    return {{"id", t.id},
            {"replicate", t.replicate},
            {"steady", s.steady},
            {"included", t.included},
            {"reason", t.exclusion_reason.empty() ? s.reason : t.exclusion_reason},
            {"rows", t.rows},
            {"window_start_s", s.window_start_s},
            {"window_end_s", s.window_end_s},
            {"max_skin_fluctuation_c", s.max_skin_fluctuation_c},
            {"worst_zone", s.worst_zone},
            {"settled_since_s", number_or_null(s.settled_since_s)},
            {"max_flux_drift_w_m2", s.max_flux_drift_w_m2},
            {"max_flux_sd_w_m2", s.max_flux_sd_w_m2},
            {"heat_loss_drift_fraction", s.heat_loss.observed ? json(s.heat_loss.drift_fraction) : json()},
            {"mean_skin_drift_c", s.heat_loss.observed ? json(s.heat_loss.mean_skin_drift_c) : json()},
            {"skin_drift", skin_drift_json(s)},
            {"whole_body_q_w_m2", number_or_null(t.whole_body_q_w_m2)}};
}

json case_json(const CaseResult& c) {
    json conditions = json::object();
    json conditions_u = json::object();
    for (const auto& ce : c.conditions) {
        conditions[ce.channel] = number_or_null(ce.e.value);
        conditions_u[ce.channel] = {{"u_a", number_or_null(ce.e.u_a)}, {"type_a_estimable", ce.e.type_a_estimable},
                                    {"u_b", ce.e.u_b}, {"u_c", ce.e.u_c}, {"k", ce.e.k}, {"U", ce.e.U}};
    }
    if (c.wettedness) conditions["wettedness"] = *c.wettedness;
    if (c.skin_setpoint_c) conditions["skin_setpoint_c"] = *c.skin_setpoint_c;
    json j{{"case", c.case_id}, {"n_replicates", c.n_replicates}, {"type_a_estimable", c.type_a_estimable},
           {"conditions", conditions},
           {"conditions_uncertainty", conditions_u}};
    if (c.n_replicates > 0) {
        j["whole_body"] = area_json(c.whole_body, false);
        json regions = json::array();
        for (const auto& r : c.regions) regions.push_back(area_json(r, true));
        j["regions"] = regions;
        json zones = json::array();
        for (const auto& z : c.zones) {
            json zj = estimate_json(z.q);
            zj["zone"] = z.zone;
            zj["name"] = z.name;
            zj["region"] = z.region;
            zj["area_m2"] = z.area_m2;
            zj["skin_temp_c"] = z.skin_temp_c;
            zones.push_back(zj);
        }
        j["zones"] = zones;
    }
    json trials = json::array();
    for (const auto& t : c.trials) trials.push_back(trial_json(t));
    j["trials"] = trials;
    j["warnings"] = c.warnings;
    return j;
}

std::string fmt_nu(double nu) { return std::isfinite(nu) ? fmt::format("{:.1f}", nu) : std::string("inf"); }
// u_A of one replicate is absent, not 0.
std::string fmt_u(double u, int width, int precision) {
    return std::isfinite(u) ? fmt::format("{:>{}.{}f}", u, width, precision) : fmt::format("{:>{}}", "n/a", width);
}

// The document without its case lists ("cases", "unanalysed_cases" are empty arrays), which
// to_json fills and write_json streams.
json head_json(const CampaignResult& r) {
    json excluded = json::array();
    for (const auto* list : {&r.cases, &r.unanalysed_cases})
        for (const auto& c : *list)
            for (const auto& t : c.trials)
                if (!t.included) excluded.push_back({{"id", t.id}, {"case", c.case_id}, {"reason", t.exclusion_reason}});
    const auto& s = r.options.steady;
    return {{"campaign", r.campaign},
            {"method",
             {{"steady_window_s", s.window_s},
              {"max_skin_fluctuation_c", s.max_skin_fluctuation_c},
              {"max_gap_s", s.max_gap_s},
              {"require_flux_stability", s.require_flux_stability},
              {"max_flux_drift_w_m2", s.max_flux_drift_w_m2},
              {"max_flux_sd_w_m2", s.max_flux_sd_w_m2},
              {"require_heat_loss_stability", s.require_heat_loss_stability},
              {"max_heat_loss_drift_fraction", s.heat_loss.max_drift_fraction},
              {"max_mean_skin_drift_c", s.heat_loss.max_mean_skin_drift_c},
              {"include_unsteady", r.options.include_unsteady},
              {"type_b_correlation", to_string(r.options.type_b_correlation)},
              {"confidence", r.options.confidence},
              {"coverage", to_string(r.options.coverage)},
              {"type_b_relative_uncertainty", r.options.type_b_relative_uncertainty},
              {"type_b_dof", number_or_null(type_b_dof(r.options.type_b_relative_uncertainty))}}},
            {"cases", json::array()},
            {"unanalysed_cases", json::array()},
            {"excluded_trials", excluded},
            {"warnings", r.warnings}};
}

const std::vector<CaseResult>* case_list(const CampaignResult& r, const std::string& key) {
    return key == "cases" ? &r.cases : key == "unanalysed_cases" ? &r.unanalysed_cases : nullptr;
}

// `value.dump(indent)` as it appears `depth` levels deep in a document dumped with `indent`.
// Strings escape their newlines, so every '\n' in a dump starts a line to indent.
std::string nested_dump(const json& value, int indent, int depth) {
    const std::string dump = value.dump(indent);
    const std::string newline = "\n" + std::string(static_cast<std::size_t>(indent * depth), ' ');
    std::string out;
    out.reserve(dump.size() + dump.size() / 8);
    std::size_t from = 0;
    for (std::size_t nl = dump.find('\n'); nl != std::string::npos; nl = dump.find('\n', from)) {
        out.append(dump, from, nl - from);
        out += newline;
        from = nl + 1;
    }
    out.append(dump, from, std::string::npos);
    return out;
}

}  // namespace

json to_json(const CampaignResult& r) {
    json j = head_json(r);
    for (const char* key : {"cases", "unanalysed_cases"})
        for (const auto& c : *case_list(r, key)) j[key].push_back(case_json(c));
    return j;
}

void write_json(std::ostream& out, const CampaignResult& r, int indent, const json& extra) {
    json head = head_json(r);
    for (const auto& [key, value] : extra.items()) head[key] = value;
    const std::string pad(static_cast<std::size_t>(std::max(indent, 0)), ' ');
    out << "{\n";
    bool first = true;
    for (const auto& [key, value] : head.items()) {  // the keys in dump()'s (sorted) order
        out << (first ? "" : ",\n") << pad << json(key).dump() << ": ";
        first = false;
        const auto* cases = case_list(r, key);
        if (!cases || cases->empty()) {
            out << nested_dump(value, indent, 1);
            continue;
        }
        out << "[\n";
        // The cases are formatted two at a time on their own threads, in order, while this one
        // writes: at most three cases' JSON in memory, whatever the campaign's size.
        in_order_ahead(
            cases->size(), 2, [&, cases](std::size_t i) { return nested_dump(case_json((*cases)[i]), indent, 2); },
            [&, cases](std::size_t i, const std::string& text) {
                out << pad << pad << text << (i + 1 < cases->size() ? ",\n" : "\n");
            });
        out << pad << "]";
    }
    out << "\n}";
}

std::string format_table(const CampaignResult& r) {
    std::string out = fmt::format("Campaign '{}': {} case(s) analysed; steady = every zone's skin temperature within "
                                  "{:.3f} °C over the final {:.0f} min; {:.0f} % expanded uncertainty (Eq. S7), "
                                  "Type B {} between zones\n",
                                  r.campaign, r.cases.size(), r.options.steady.max_skin_fluctuation_c,
                                  r.options.steady.window_s / 60.0, r.options.confidence * 100.0,
                                  to_string(r.options.type_b_correlation));
    const bool paper_k = r.options.coverage == Coverage::replicates_t;
    const double nu_b = type_b_dof(r.options.type_b_relative_uncertainty);
    out += paper_k ? "k = t(n - 1) from the replicates as in Text S3 (--coverage paper)"
                   : "k = t(ν_eff), Welch-Satterthwaite (GUM G.4; the paper uses t(n - 1), --coverage paper)";
    out += std::isfinite(nu_b) ? fmt::format("; Type B dof {:.1f} (GUM G.4.2)\n", nu_b) : std::string("\n");
    auto row = [](const std::string& name, const Estimate& e) {
        return fmt::format("  {:<14} {:>9.2f} {} {:>7.2f} {:>7.2f} {:>6} {:>6.3f} {:>7.2f}\n", name, e.value,
                           fmt_u(e.u_a, 7, 2), e.u_b, e.u_c, fmt_nu(e.k_dof), e.k, e.U);
    };
    for (const auto& c : r.cases) {
        out += fmt::format("\nCase {} (n = {})", c.case_id, c.n_replicates);
        for (const auto& ce : c.conditions)
            out += fmt::format("  {} {:.2f} ± {:.2f}", ce.channel, ce.e.value, ce.e.U);
        if (c.wettedness) out += fmt::format("  wettedness {:.2g}", *c.wettedness);
        out += "\n";
        for (const auto& t : c.trials) {
            out += fmt::format("  trial {:<10} {:<9} window {:>6.0f}-{:<6.0f} s  max skin ΔT {:.3f} °C (zone {:02})",
                               t.id, t.included ? (t.steady.steady ? "steady" : "INCLUDED") : "EXCLUDED",
                               t.steady.window_start_s, t.steady.window_end_s, t.steady.max_skin_fluctuation_c,
                               t.steady.worst_zone);
            if (t.steady.worst_skin_drift_zone != 0)  // the trend the range rule cannot see
                out += fmt::format("  drift {:+.3f} ± {:.3f} °C/30 min (zone {:02})", t.steady.max_skin_drift_c_per_30min,
                                   t.steady.u_max_skin_drift_c_per_30min, t.steady.worst_skin_drift_zone);
            if (!t.included) out += "  " + t.exclusion_reason;
            else if (!t.steady.steady) out += "  not steady: " + t.steady.reason;
            out += "\n";
        }
        out += fmt::format("  {:<14} {:>9} {:>7} {:>7} {:>7} {:>6} {:>6} {:>7}\n", "Q, W/m²", "mean", "u_A", "u_B", "u_C",
                           paper_k ? "n-1" : "ν_eff", "k", "U");
        out += row("whole body", c.whole_body.q);
        for (const auto& a : c.regions) out += row(a.name, a.q);
        out += "  Budget, whole body (contribution to u_C and share of u_C²):\n";
        const auto& wb = c.whole_body.q;
        for (const auto& b : c.whole_body.budget) {
            out += fmt::format("    {:<48} {} W/m²  {:>5.1f} %\n", b.type == 'A' ? b.source : "  of which " + b.part,
                               fmt_u(b.u_w_m2, 7, 3), 100.0 * b.share);
            if (b.type == 'A')  // the Type B subtotal, then its parts
                out += fmt::format("    {:<48} {:>7.3f} W/m²  {:>5.1f} %\n",
                                   fmt::format("Type B: all heat-flux sensors ({})", to_string(r.options.type_b_correlation)),
                                   wb.u_b, wb.u_c > 0.0 ? 100.0 * wb.u_b * wb.u_b / (wb.u_c * wb.u_c) : 0.0);
        }
        for (const auto& w : c.warnings) out += "  warning: " + w + "\n";
    }
    for (const auto& c : r.unanalysed_cases) {
        out += fmt::format("\nCase {}: NO RESULTS, every trial excluded\n", c.case_id);
        for (const auto& t : c.trials) out += fmt::format("  trial {:<10} {}\n", t.id, t.exclusion_reason);
    }
    return out;
}

std::string format_csv(const CampaignResult& r) {
    std::string out = "case,level,name,area_m2,n_replicates,q_w_m2,u_a_w_m2,u_b_w_m2,u_c_w_m2,nu_eff,k,U_w_m2\n";
    auto line = [&](int case_id, const char* level, const std::string& name, double area, int n, const Estimate& e) {
        out += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{}\n", case_id, level, name, area, n, e.value, e.u_a, e.u_b,
                           e.u_c, std::isfinite(e.nu_eff) ? fmt::format("{}", e.nu_eff) : std::string("inf"), e.k, e.U);
    };
    for (const auto& c : r.cases) {
        line(c.case_id, "whole_body", "whole_body", c.whole_body.area_m2, c.n_replicates, c.whole_body.q);
        for (const auto& a : c.regions) line(c.case_id, "region", a.name, a.area_m2, c.n_replicates, a.q);
        for (const auto& z : c.zones) line(c.case_id, "zone", z.name, z.area_m2, c.n_replicates, z.q);
    }
    return out;
}

}  // namespace manikind::analysis
