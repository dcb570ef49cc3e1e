#include "analysis/physio.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>

#include <fmt/core.h>

#include "analysis/input_error.hpp"
#include "analysis/plot/svg_figure.hpp"
#include "analysis/uncertainty.hpp"
#include "physics/thermoreg/stolwijk.hpp"

namespace manikind::analysis::physio {

namespace tr = physics::thermoreg;

namespace {

// One coupling step as the trial recorded it: what the model was given and what it gave.
struct CouplingStep {
    double t_s = 0.0;
    tr::SegmentValues loss_w{};
    tr::Environment env;
    double core_c = 0.0, skin_c = 0.0, sweat_g_h = 0.0, metabolic_w = 0.0, respiration_w = 0.0, storage_w = 0.0;
    // What the loop took out of the heaters' power for warming each segment's shell, and the
    // shell capacity's relative standard uncertainty (0 in recordings from before issue 63).
    tr::SegmentValues shell_w{};
    double shell_u_rel = 0.0;
    bool fallback = false;
};

struct Recorded {
    double met = 1.5;
    bool fell_back = false;
    std::vector<CouplingStep> steps;
};

// The model's channels of one trial at the rows where the loop recorded a coupling step.
std::optional<Recorded> recorded_steps(const Campaign& c, const Trial& t) {
    std::map<std::string, std::size_t> index;
    for (std::size_t i = 0; i < c.channels.size(); ++i)
        if (c.channels[i].device == "model") index[c.channels[i].name] = i;
    if (!index.count("time_s") || t.data.channel_values.empty()) return std::nullopt;
    const auto& names = tr::segment_names();
    std::vector<std::string> needed = {"core_temp_c", "mean_skin_temp_c", "air_temp_c", "air_rh_pct", "mrt_c",
                                       "air_speed_m_s", "metabolic_met", "sweat_rate_g_h", "metabolic_w",
                                       "respiration_loss_w", "storage_w"};
    for (const char* s : names) needed.push_back(std::string(s) + ".heat_loss_w");
    for (const auto& n : needed)
        if (!index.count(n))
            throw InputError(t.info.file, 0, 0, "model." + n,
                             "a physiological trial's model channels are incomplete: model." + n + " is missing");
    for (const auto& [name, i] : index)
        if (i >= t.data.channel_values.size() || t.data.channel_values[i].size() != t.data.rows() ||
            i >= t.data.channel_quality.size() || t.data.channel_quality[i].size() != t.data.rows())
            throw InputError(t.info.file, 0, 0, "model." + name, "model." + name + " does not have a value or an empty cell in every row");
    auto value = [&](const std::string& name, std::size_t row) { return t.data.channel_values[index.at(name)][row]; };
    auto present = [&](const std::string& name, std::size_t row) {
        return t.data.channel_quality[index.at(name)][row] != kNoSample;
    };
    Recorded r;
    const bool has_fallback = index.count("fallback") != 0;
    for (std::size_t row = 0; row < t.data.rows(); ++row) {
        // The loop records fallback = 1 when it falls back: the model no longer drove the manikin.
        if (has_fallback && present("fallback", row) && value("fallback", row) > 0.0) {  // a 5-s bin may hold a 0 too
            r.fell_back = true;
            break;
        }
        if (!present("time_s", row)) continue;
        CouplingStep s;
        s.t_s = value("time_s", row);
        for (const auto& n : needed)
            if (!present(n, row) || !std::isfinite(value(n, row)))
                throw InputError(t.info.file, row + 2, 0, "model." + n,
                                 fmt::format("model.{} has no value where model.time_s = {} s", n, s.t_s));
        for (std::size_t i = 0; i < names.size(); ++i) s.loss_w[i] = value(std::string(names[i]) + ".heat_loss_w", row);
        s.env = {value("air_temp_c", row), value("mrt_c", row), value("air_rh_pct", row), value("air_speed_m_s", row)};
        s.core_c = value("core_temp_c", row);
        s.skin_c = value("mean_skin_temp_c", row);
        s.sweat_g_h = value("sweat_rate_g_h", row);
        s.metabolic_w = value("metabolic_w", row);
        s.respiration_w = value("respiration_loss_w", row);
        s.storage_w = value("storage_w", row);
        auto optional_value = [&](const std::string& name) {
            return index.count(name) && present(name, row) && std::isfinite(value(name, row)) ? value(name, row) : 0.0;
        };
        for (std::size_t i = 0; i < names.size(); ++i) s.shell_w[i] = optional_value(std::string(names[i]) + ".shell_storage_w");
        if (const double cap = optional_value("shell_heat_capacity_j_m2k"); cap > 0.0)
            s.shell_u_rel = optional_value("shell_heat_capacity_u_j_m2k") / cap;
        if (!r.steps.empty() && value("metabolic_met", row) != r.met)
            throw InputError(t.info.file, row + 2, 0, "model.metabolic_met",
                             fmt::format("model.metabolic_met changes within the trial ({} then {})", r.met,
                                         value("metabolic_met", row)));
        r.met = value("metabolic_met", row);
        // A plan's model runs at most 24 h (a day and a half leaves room), and the loop steps at
        // most every 600 s ([physiological] coupling_period_s): both bound the replay's cost.
        const double previous_s = r.steps.empty() ? 0.0 : r.steps.back().t_s;
        if (!(s.t_s > previous_s) || s.t_s > 1.5 * 86400.0)
            throw InputError(t.info.file, row + 2, 0, "model.time_s", fmt::format("model.time_s = {} s does not advance", s.t_s));
        if (s.t_s - previous_s > 600.0 + 1e-6)
            throw InputError(t.info.file, row + 2, 0, "model.time_s",
                             fmt::format("model.time_s jumps {:.0f} s: the loop records a step at least every 600 s",
                                         s.t_s - previous_s));
        r.steps.push_back(s);
    }
    if (r.steps.empty() && !r.fell_back) return std::nullopt;
    return r;
}

struct Replayed {
    std::vector<double> core_c, skin_c;
};

// The model stepped 1 s at a time through the recorded coupling steps; `measured` false runs it
// without the manikin (its own exchange) in the same conditions.
Replayed replay(const Recorded& r, tr::ConvectionModel convection, bool measured,
                const std::vector<tr::SegmentValues>& losses, const std::vector<tr::Environment>& envs) {
    tr::ModelOptions o;
    o.convection = convection;
    o.clo = 0.0;
    tr::Body body(r.met, o);
    Replayed out;
    for (std::size_t k = 0; k < r.steps.size(); ++k) {
        const tr::StepState* st = nullptr;
        while (body.time_s() + 1.0 <= r.steps[k].t_s + 1e-9) st = &body.step(1.0, envs[k], measured ? &losses[k] : nullptr);
        out.core_c.push_back(st ? st->sample.core_temp_c : std::nan(""));
        out.skin_c.push_back(st ? st->sample.mean_skin_temp_c : std::nan(""));
    }
    return out;
}

// A drawn error of an instrument at a reading (Type B Monte Carlo).
double draw_error(std::mt19937_64& rng, const InstrumentSpec& spec, double reading) {
    return standardised_error_draw(spec.distribution, rng) * spec.limit(reading);
}

// Where the loop's core and mean skin lie within the band of their difference from the model alone.
Agreement agreement_of(const std::vector<Point>& points) {
    Agreement a;
    for (const auto& p : points) {
        if (!std::isfinite(p.diff_core_u95_c) || !std::isfinite(p.diff_skin_u95_c)) continue;
        ++a.points;
        const double d_core = std::abs(p.core_temp_c - p.alone_coupled_core_c), d_skin = std::abs(p.mean_skin_temp_c - p.alone_coupled_skin_c);
        a.core_within += d_core <= p.diff_core_u95_c ? 1 : 0;
        a.skin_within += d_skin <= p.diff_skin_u95_c ? 1 : 0;
        if (d_skin >= a.worst_skin_c) a.worst_skin_c = d_skin, a.worst_skin_u95_c = p.diff_skin_u95_c;
    }
    a.agrees = a.points > 0 && a.core_within >= 0.95 * a.points && a.skin_within >= 0.95 * a.points;
    return a;
}

double quantile(std::vector<double> v, double p) {
    std::sort(v.begin(), v.end());
    const double pos = p * static_cast<double>(v.size() - 1);
    const auto i = static_cast<std::size_t>(pos);
    return i + 1 < v.size() ? v[i] + (pos - static_cast<double>(i)) * (v[i + 1] - v[i]) : v.back();
}

}  // namespace

Result compute(const Campaign& campaign, const Options& options) {
    Result result;
    const InstrumentSpec flux = campaign.instrument("heat_flux_w_m2"), air = campaign.instrument("air_temp_c"),
                         rh = campaign.instrument("air_rh_pct"), wall = campaign.instrument("wall_temp_c"),
                         speed = campaign.instrument("air_speed_m_s");
    // Each zone's model segment by the default [physiological.segments] map (the record does not
    // say which map a trial ran with), and the zones' area per model segment.
    std::map<std::string, int> segment_of;
    for (const auto& [model_segment, zone_segments] : default_model_segments())
        for (std::size_t m = 0; m < tr::segment_names().size(); ++m)
            if (model_segment == tr::segment_names()[m])
                for (const auto& zs : zone_segments) segment_of[zs] = static_cast<int>(m);
    tr::SegmentValues zone_area{};
    for (const auto& z : campaign.zone_map.zones)
        if (const auto it = segment_of.find(z.segment); it != segment_of.end())
            zone_area[static_cast<std::size_t>(it->second)] += z.area_m2;
    const auto& model_areas = tr::Body::segment_areas_m2();
    std::map<int, std::vector<std::size_t>> trials_of_case;
    for (const auto& t : campaign.trials) {
        const auto rec = recorded_steps(campaign, t);
        if (!rec) continue;
        TrialTrajectory tt;
        tt.trial = t.info.id;
        tt.case_id = t.info.case_id;
        tt.replicate = t.info.replicate;
        tt.coupling_period_s = rec->steps.size() > 1    ? rec->steps[1].t_s - rec->steps[0].t_s
                               : rec->steps.size() == 1 ? rec->steps[0].t_s
                                                        : std::nan("");
        std::vector<tr::SegmentValues> losses;
        std::vector<tr::Environment> envs;
        for (const auto& s : rec->steps) losses.push_back(s.loss_w), envs.push_back(s.env);
        tt.fell_back = rec->fell_back;
        const Recorded& r = *rec;
        const std::size_t used = r.steps.size();
        Replayed nominal, coupled, dt_only;
        try {
            nominal = replay(r, tr::ConvectionModel::coupled, true, losses, envs);
            coupled = replay(r, tr::ConvectionModel::coupled, false, losses, envs);
            dt_only = replay(r, tr::ConvectionModel::dt_only, false, losses, envs);
        } catch (const std::domain_error& e) {
            // Values no model run could have recorded (a hand-edited or damaged file).
            throw InputError(t.info.file, 0, 0, "model", fmt::format("the recorded model inputs cannot be replayed: {}", e.what()));
        }
        // Type B: the replay under drawn instrument errors. The manikin's flux calibration, its
        // offset and its gain, is one error common to every zone, as `manikin analyze` (its
        // default, r = 1) and `manikin clothing` model it (issue 63: the same manikin was modelled
        // with per-zone offsets here); the probes' offsets per draw.
        std::mt19937_64 rng(options.seed ^ (static_cast<std::uint64_t>(t.info.case_id) << 20) ^ static_cast<std::uint64_t>(t.info.replicate));
        std::vector<std::vector<double>> core_draws(used), skin_draws(used), loss_draws(used);
        std::vector<std::vector<double>> alone_core_draws(used), alone_skin_draws(used), diff_core_draws(used), diff_skin_draws(used);
        const InstrumentSpec gain_spec{0.0, flux.accuracy_of_reading, flux.distribution};
        const InstrumentSpec offset_spec{flux.accuracy, 0.0, flux.distribution};
        for (int d = 0; d < options.draws; ++d) {
            const double flux_gain = draw_error(rng, gain_spec, 1.0);  // a fraction of the reading
            tr::SegmentValues offset_w{};  // per segment: the common offset over its zones' area
            const double offset_w_m2 = draw_error(rng, offset_spec, 0.0);
            for (const auto& z : campaign.zone_map.zones)
                if (const auto it = segment_of.find(z.segment); it != segment_of.end())
                    offset_w[static_cast<std::size_t>(it->second)] += offset_w_m2 * z.area_m2;
            const double air_e = draw_error(rng, air, envs[0].air_temp_c);
            const double rh_e = draw_error(rng, rh, envs[0].rh_pct);
            const double wall_e = draw_error(rng, wall, envs[0].mrt_c);
            // The shell's capacity, off by its stated standard uncertainty (normal): the storage
            // the loop subtracted scales with it.
            const double shell_e = std::normal_distribution<double>(0.0, 1.0)(rng);
            const double speed_e = draw_error(rng, speed, envs[0].air_speed_m_s);
            auto l = losses;
            auto e = envs;
            for (std::size_t k = 0; k < used; ++k) {
                for (std::size_t i = 0; i < l[k].size(); ++i)
                    l[k][i] = l[k][i] * (1.0 + flux_gain) + (zone_area[i] > 0 ? offset_w[i] / zone_area[i] * model_areas[i] : 0.0) -
                              shell_e * r.steps[k].shell_u_rel * r.steps[k].shell_w[i];
                e[k].air_temp_c += air_e;
                e[k].rh_pct = std::clamp(e[k].rh_pct + rh_e, 0.0, 100.0);
                e[k].mrt_c += wall_e;
                e[k].air_speed_m_s = std::max(0.0, e[k].air_speed_m_s + speed_e);
            }
            try {
                // The loop and the model alone under the same drawn conditions: their difference's
                // band holds what the probes could move in both alike.
                const auto rp = replay(r, tr::ConvectionModel::coupled, true, l, e);
                const auto ra = replay(r, tr::ConvectionModel::coupled, false, l, e);
                for (std::size_t k = 0; k < used; ++k) {
                    core_draws[k].push_back(rp.core_c[k]);
                    skin_draws[k].push_back(rp.skin_c[k]);
                    alone_core_draws[k].push_back(ra.core_c[k]);
                    alone_skin_draws[k].push_back(ra.skin_c[k]);
                    diff_core_draws[k].push_back(rp.core_c[k] - ra.core_c[k]);
                    diff_skin_draws[k].push_back(rp.skin_c[k] - ra.skin_c[k]);
                    double q = 0.0;
                    for (double v : l[k]) q += v;
                    loss_draws[k].push_back(q);
                }
            } catch (const std::domain_error&) {
                // A draw the explicit scheme cannot take is not a trajectory: left out.
            }
        }
        for (std::size_t k = 0; k < used; ++k) {
            const auto& s = r.steps[k];
            Point p;
            p.t_s = s.t_s;
            p.core_temp_c = s.core_c;
            p.mean_skin_temp_c = s.skin_c;
            double q = 0.0;
            for (double v : s.loss_w) q += v;
            p.heat_loss_w = q;
            auto half_width = [](const std::vector<double>& v) {
                return v.size() >= 20 ? 0.5 * (quantile(v, 0.975) - quantile(v, 0.025)) : std::nan("");
            };
            p.core_u95_c = half_width(core_draws[k]);
            p.mean_skin_u95_c = half_width(skin_draws[k]);
            p.heat_loss_u95_w = half_width(loss_draws[k]);
            p.sweat_rate_g_h = s.sweat_g_h;
            p.metabolic_w = s.metabolic_w;
            p.respiration_loss_w = s.respiration_w;
            p.storage_w = s.storage_w;
            p.alone_coupled_core_c = coupled.core_c[k];
            p.alone_coupled_skin_c = coupled.skin_c[k];
            p.alone_dt_only_core_c = dt_only.core_c[k];
            p.alone_dt_only_skin_c = dt_only.skin_c[k];
            p.alone_core_u95_c = half_width(alone_core_draws[k]);
            p.alone_skin_u95_c = half_width(alone_skin_draws[k]);
            p.diff_core_u95_c = half_width(diff_core_draws[k]);
            p.diff_skin_u95_c = half_width(diff_skin_draws[k]);
            tt.replay_max_abs_diff_c = std::max({tt.replay_max_abs_diff_c, std::abs(nominal.core_c[k] - s.core_c),
                                                 std::abs(nominal.skin_c[k] - s.skin_c)});
            tt.points.push_back(p);
        }
        tt.agreement = agreement_of(tt.points);
        trials_of_case[tt.case_id].push_back(result.trials.size());
        result.trials.push_back(std::move(tt));
    }
    // Per case: the replicates' mean at each model time they share; U95 from Type A (the
    // replicates) and Type B (the mean of their Monte Carlo half-widths, taken as 95 % at k = 1.96).
    for (const auto& entry : trials_of_case) {
        // Not a structured binding: clang 14 refuses to capture one in the lambdas below.
        const int case_id = entry.first;
        const std::vector<std::size_t>& idx = entry.second;
        CaseTrajectory ct;
        ct.case_id = case_id;
        ct.replicates = static_cast<int>(idx.size());
        // The model times the replicates share (the same coupling period): a replicate coupled
        // differently ends the shared part where its times part.
        std::size_t shared = SIZE_MAX;
        for (auto i : idx) shared = std::min(shared, result.trials[i].points.size());
        for (std::size_t k = 0; k < shared; ++k)
            for (auto i : idx)
                if (std::abs(result.trials[i].points[k].t_s - result.trials[idx[0]].points[k].t_s) > 1e-6) shared = k;
        for (std::size_t k = 0; k < shared; ++k) {
            Point p = result.trials[idx[0]].points[k];
            // The replicates' mean of a value with no band of its own.
            auto mean_over = [&](auto value) {
                std::vector<double> v;
                for (auto i : idx) v.push_back(value(result.trials[i].points[k]));
                return mean(v);
            };
            auto combine = [&](auto value, auto u95, double& mean_out, double& u95_out, double* repro_out = nullptr) {
                std::vector<double> v;
                double ub = 0.0;
                for (auto i : idx) v.push_back(value(result.trials[i].points[k])), ub += u95(result.trials[i].points[k]) / 1.96;
                ub /= static_cast<double>(idx.size());
                mean_out = mean(v);
                if (repro_out && v.size() >= 2) {
                    // A further run: its departure from the mean of n has variance s² (1 + 1/n), on
                    // n - 1 degrees of freedom (a prediction interval; GUM G.3 for t).
                    const double ua_mean = type_a_of_mean(v);
                    const double n = static_cast<double>(v.size());
                    *repro_out = std::isfinite(ua_mean) ? coverage_factor(n - 1.0) * ua_mean * std::sqrt(n + 1.0) : std::nan("");
                }
                if (!std::isfinite(ub)) {  // too few Monte Carlo draws replayed: no band
                    u95_out = std::nan("");
                    return;
                }
                if (v.size() < 2) {
                    u95_out = 1.96 * ub;
                    return;
                }
                const double ua = type_a_of_mean(v);
                if (!std::isfinite(ua) || !std::isfinite(mean_out)) {
                    u95_out = std::nan("");
                    return;
                }
                const double uc = std::sqrt(ua * ua + ub * ub);
                if (uc == 0.0) {
                    u95_out = 0.0;
                    return;
                }
                const double nu = welch_satterthwaite({{ua, static_cast<double>(v.size() - 1)}, {ub, kInfiniteDof}});
                u95_out = coverage_factor(nu) * uc;
            };
            combine([](const Point& q) { return q.core_temp_c; }, [](const Point& q) { return q.core_u95_c; }, p.core_temp_c,
                    p.core_u95_c, &p.core_repro_u95_c);
            combine([](const Point& q) { return q.mean_skin_temp_c; }, [](const Point& q) { return q.mean_skin_u95_c; },
                    p.mean_skin_temp_c, p.mean_skin_u95_c, &p.skin_repro_u95_c);
            // The model alone, and the difference loop minus alone, over the replicates alike.
            combine([](const Point& q) { return q.alone_coupled_core_c; }, [](const Point& q) { return q.alone_core_u95_c; },
                    p.alone_coupled_core_c, p.alone_core_u95_c);
            combine([](const Point& q) { return q.alone_coupled_skin_c; }, [](const Point& q) { return q.alone_skin_u95_c; },
                    p.alone_coupled_skin_c, p.alone_skin_u95_c);
            double unused = 0.0;
            combine([](const Point& q) { return q.core_temp_c - q.alone_coupled_core_c; }, [](const Point& q) { return q.diff_core_u95_c; },
                    unused, p.diff_core_u95_c);
            combine([](const Point& q) { return q.mean_skin_temp_c - q.alone_coupled_skin_c; },
                    [](const Point& q) { return q.diff_skin_u95_c; }, unused, p.diff_skin_u95_c);
            p.alone_dt_only_core_c = mean_over([](const Point& q) { return q.alone_dt_only_core_c; });
            p.alone_dt_only_skin_c = mean_over([](const Point& q) { return q.alone_dt_only_skin_c; });
            combine([](const Point& q) { return q.heat_loss_w; }, [](const Point& q) { return q.heat_loss_u95_w; }, p.heat_loss_w,
                    p.heat_loss_u95_w);
            p.sweat_rate_g_h = mean_over([](const Point& q) { return q.sweat_rate_g_h; });
            ct.points.push_back(p);
        }
        ct.agreement = agreement_of(ct.points);
        result.cases.push_back(std::move(ct));
    }
    return result;
}

namespace {
// One replicate has no reproducibility band: null, as JSON readers expect, not a NaN number.
nlohmann::json finite_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

nlohmann::json point_json(const Point& p) {
    return {{"t_s", p.t_s},
            {"core_temp_c", p.core_temp_c},
            {"core_temp_U95_c", p.core_u95_c},
            {"mean_skin_temp_c", p.mean_skin_temp_c},
            {"mean_skin_temp_U95_c", p.mean_skin_u95_c},
            {"heat_loss_w", p.heat_loss_w},
            {"heat_loss_U95_w", p.heat_loss_u95_w},
            {"sweat_rate_g_h", p.sweat_rate_g_h},
            {"core_temp_reproducibility_U95_c", finite_or_null(p.core_repro_u95_c)},
            {"mean_skin_temp_reproducibility_U95_c", finite_or_null(p.skin_repro_u95_c)}};
}

nlohmann::json agreement_json(const Agreement& a) {
    return {{"agrees", a.agrees},
            {"points", a.points},
            {"core_within", a.core_within},
            {"mean_skin_within", a.skin_within},
            {"worst_mean_skin_difference_c", a.worst_skin_c},
            {"worst_mean_skin_difference_U95_c", a.worst_skin_u95_c}};
}
}  // namespace

nlohmann::json to_json(const Result& r) {
    auto points = [](const std::vector<Point>& ps) {
        nlohmann::json a = nlohmann::json::array();
        for (const auto& p : ps) {
            nlohmann::json j = point_json(p);  // what results_json keeps, then the rest
            j["metabolic_w"] = p.metabolic_w;
            j["respiration_loss_w"] = p.respiration_loss_w;
            j["storage_w"] = p.storage_w;
            j["model_alone"] = {{"coupled",
                                 {{"core_temp_c", p.alone_coupled_core_c},
                                  {"core_temp_U95_c", p.alone_core_u95_c},
                                  {"mean_skin_temp_c", p.alone_coupled_skin_c},
                                  {"mean_skin_temp_U95_c", p.alone_skin_u95_c},
                                  {"difference_core_U95_c", p.diff_core_u95_c},
                                  {"difference_mean_skin_U95_c", p.diff_skin_u95_c}}},
                                {"dt_only", {{"core_temp_c", p.alone_dt_only_core_c}, {"mean_skin_temp_c", p.alone_dt_only_skin_c}}}};
            a.push_back(std::move(j));
        }
        return a;
    };
    nlohmann::json j = {{"trials", nlohmann::json::array()}, {"cases", nlohmann::json::array()}};
    for (const auto& t : r.trials)
        j["trials"].push_back({{"trial", t.trial},
                               {"case", t.case_id},
                               {"replicate", t.replicate},
                               {"coupling_period_s", t.coupling_period_s},
                               {"replay_max_abs_diff_c", t.replay_max_abs_diff_c},
                               {"fell_back", t.fell_back},
                               {"agreement_with_model_alone", agreement_json(t.agreement)},
                               {"points", points(t.points)}});
    for (const auto& c : r.cases)
        j["cases"].push_back({{"case", c.case_id},
                              {"replicates", c.replicates},
                              {"agreement_with_model_alone", agreement_json(c.agreement)},
                              {"points", points(c.points)}});
    return j;
}

nlohmann::json results_json(const Result& r) {
    nlohmann::json cases = nlohmann::json::array();
    for (const auto& c : r.cases) {
        nlohmann::json points = nlohmann::json::array();
        double next_s = 0.0;
        for (const auto& p : c.points)
            if (p.t_s + 1e-9 >= next_s) {
                points.push_back(point_json(p));
                next_s = p.t_s + 60.0;
            }
        nlohmann::json one = {{"case", c.case_id}, {"replicates", c.replicates}, {"points", points}};
        if (!c.points.empty()) one["final"] = point_json(c.points.back());
        cases.push_back(one);
    }
    nlohmann::json fell_back = nlohmann::json::array();
    for (const auto& t : r.trials)
        if (t.fell_back) fell_back.push_back(t.trial);
    return {{"cases", cases}, {"fell_back_trials", fell_back}};
}

std::string summary_text(const nlohmann::json& j) {
    std::string out;
    for (const auto& c : j.value("cases", nlohmann::json::array())) {
        if (!c.contains("final")) continue;
        const auto& f = c["final"];
        out += fmt::format("  case {} (physiological, {} replicate{}): after {:.0f} min of the model, core {:.2f} ± {:.2f} °C, "
                           "mean skin {:.2f} ± {:.2f} °C, measured loss {:.0f} ± {:.0f} W (trajectories: manikin physio)\n",
                           c.value("case", 0), c.value("replicates", 0), c.value("replicates", 0) == 1 ? "" : "s",
                           f.value("t_s", 0.0) / 60.0, f.value("core_temp_c", 0.0), f.value("core_temp_U95_c", 0.0),
                           f.value("mean_skin_temp_c", 0.0), f.value("mean_skin_temp_U95_c", 0.0), f.value("heat_loss_w", 0.0),
                           f.value("heat_loss_U95_w", 0.0));
        // With replicates: where a further run is expected (null with one replicate, or in a
        // result stored before issue 63).
        const auto& rc = f.value("core_temp_reproducibility_U95_c", nlohmann::json());
        const auto& rs = f.value("mean_skin_temp_reproducibility_U95_c", nlohmann::json());
        if (rc.is_number() && rs.is_number())
            out += fmt::format("    a further run on this manikin and chamber: core within ± {:.2f} °C, mean skin within ± {:.2f} °C "
                               "of these means (95 %, from the replicates' spread)\n",
                               rc.get<double>(), rs.get<double>());
    }
    const auto fb = j.value("fell_back_trials", nlohmann::json::array());
    if (!fb.empty()) out += fmt::format("  {} physiological trial(s) fell back to constant skin temperature: {}\n", fb.size(), fb.dump());
    return out;
}

std::string svg(const Result& r, const std::string& title) {
    namespace pl = plot;
    pl::Figure fig;
    fig.width_px = 760;
    fig.height_px = 720;
    fig.title = title;
    pl::XYPanel temps, heat;
    temps.box = {0, 34, 760, 320};
    heat.box = {0, 364, 760, 350};
    temps.x.label = heat.x.label = "Model time (min)";
    temps.y.label = "Temperature (°C)";
    heat.y.label = "Heat loss (W, + = lost); sweat (g/h)";
    const char* colours[] = {"#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"};
    std::size_t ci = 0;
    for (const auto& c : r.cases) {
        const std::string tag = r.cases.size() > 1 ? fmt::format("case {} ", c.case_id) : "";
        // The trajectory as a line at every coupling step; its 95 % band as bars every 10 min
        // (bars at every step hide the line).
        auto series = [&](pl::XYPanel& panel, const std::string& label, const std::string& colour, auto y, auto u, bool band) {
            pl::Series s;
            s.label = label;
            s.colour = colour;
            s.line = true;
            s.markers = false;
            pl::Series bars;
            bars.colour = colour;
            bars.markers = false;
            double next_s = 0.0;
            for (const auto& p : c.points) {
                s.x.push_back(p.t_s / 60.0);
                s.y.push_back(y(p));
                if (band && p.t_s + 1e-9 >= next_s && std::isfinite(u(p))) {
                    bars.x.push_back(p.t_s / 60.0);
                    bars.y.push_back(y(p));
                    bars.y_err.push_back(u(p));
                    next_s = p.t_s + 600.0;
                }
            }
            panel.series.push_back(s);
            if (band && !bars.x.empty()) panel.series.push_back(bars);
            return s;
        };
        const std::string a = colours[ci++ % 6], b = colours[ci++ % 6];
        series(temps, tag + "core (± U95 every 10 min)", a, [](const Point& p) { return p.core_temp_c; },
               [](const Point& p) { return p.core_u95_c; }, true);
        series(temps, tag + "mean skin (± U95)", b, [](const Point& p) { return p.mean_skin_temp_c; },
               [](const Point& p) { return p.mean_skin_u95_c; }, true);
        pl::XYPanel scratch;
        auto alone = series(scratch, tag + "model alone (coupled): core", a, [](const Point& p) { return p.alone_coupled_core_c; },
                            [](const Point&) { return 0.0; }, false);
        alone.dash = "5 4";
        temps.series.push_back(alone);
        auto alone_skin = series(scratch, tag + "model alone (coupled): skin", b,
                                 [](const Point& p) { return p.alone_coupled_skin_c; }, [](const Point&) { return 0.0; }, false);
        alone_skin.dash = "5 4";
        temps.series.push_back(alone_skin);
        series(heat, tag + "measured heat loss (± U95)", a, [](const Point& p) { return p.heat_loss_w; },
               [](const Point& p) { return p.heat_loss_u95_w; }, true);
        series(heat, tag + "sweat (g/h)", b, [](const Point& p) { return p.sweat_rate_g_h; }, [](const Point&) { return 0.0; },
               false);
    }
    for (auto* panel : {&temps, &heat}) {
        panel->legend_outside = true;
        panel->min_left_margin_px = 70.0;
        panel->min_legend_width_px = 190.0;
    }
    fig.xy_panels = {std::move(temps), std::move(heat)};
    return pl::to_svg(fig);
}

}  // namespace manikind::analysis::physio
