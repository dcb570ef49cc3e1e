#include "analysis/clothing.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>

#include <boost/math/distributions/students_t.hpp>
#include <fmt/core.h>

#include "physics/psychrometrics.hpp"

namespace manikind::analysis::clothing {
namespace {

// One trial of a clothing test, as the steady window left it.
struct TestTrial {
    std::string ensemble, test, id;
    const TrialResult* r = nullptr;
    const Campaign* campaign = nullptr;
};

// Instrument errors shared by every trial (one draw of the Monte Carlo), in units of each
// spec's limit (a standardised draw from its distribution): the same manikin and probes
// measured every trial, so their calibration errors are common (docs/clothing.md, "Type B").
struct Draw {
    double flux_offset = 0.0, flux_gain = 0.0, air = 0.0, skin = 0.0, rh = 0.0;
};

// The trial's values under a draw of the instrument errors.
struct Perturbed {
    double air_temp_c = 0.0, air_rh_pct = 0.0;
    std::vector<double> skin_c, q_w_m2;  // per zone; NaN where missing
};

Perturbed perturb(const TestTrial& t, const Draw& d) {
    const Campaign& c = *t.campaign;
    const auto flux = c.instrument("heat_flux_w_m2"), air = c.instrument("air_temp_c"), skin = c.instrument("skin_temp_c"),
               rh = c.instrument("air_rh_pct");
    Perturbed p;
    p.air_temp_c = t.r->air_temp_c + d.air * air.limit(t.r->air_temp_c);
    p.air_rh_pct = std::clamp(t.r->air_rh_pct + d.rh * rh.limit(t.r->air_rh_pct), 0.0, 100.0);
    p.skin_c.resize(t.r->zone_skin_temp_c.size());
    p.q_w_m2.resize(t.r->zone_q_w_m2.size());
    for (std::size_t z = 0; z < p.skin_c.size(); ++z) p.skin_c[z] = t.r->zone_skin_temp_c[z] + d.skin * skin.limit(t.r->zone_skin_temp_c[z]);
    for (std::size_t z = 0; z < p.q_w_m2.size(); ++z) {
        const double q = t.r->zone_q_w_m2[z];
        p.q_w_m2[z] = q + d.flux_offset * flux.accuracy + d.flux_gain * flux.accuracy_of_reading * std::abs(q);
    }
    return p;
}

// Area fractions over the zones with a value in both channels (and optionally a zone subset).
struct Weights {
    std::vector<std::size_t> zones;
    std::vector<double> f;
};
Weights weights(const ZoneMap& map, const Perturbed& p, const std::string& region = "") {
    Weights w;
    double area = 0.0;
    for (std::size_t z = 0; z < map.zones.size() && z < p.q_w_m2.size() && z < p.skin_c.size(); ++z) {
        if (!region.empty() && map.zones[z].region != region) continue;
        if (!std::isfinite(p.q_w_m2[z]) || !std::isfinite(p.skin_c[z])) continue;
        w.zones.push_back(z);
        w.f.push_back(map.zones[z].area_m2);
        area += map.zones[z].area_m2;
    }
    for (double& f : w.f) f /= area > 0.0 ? area : 1.0;
    return w;
}

// Every quantity of one evaluation (the data as measured, or one Monte Carlo draw).
struct Quantities {
    // Per ensemble: the replicates' values of each primary key, and the means and derived keys.
    std::map<std::string, std::map<std::string, std::vector<double>>> replicates;
    std::map<std::string, std::map<std::string, double>> value;
    std::map<std::string, double> fcl;         // NaN: no source
    std::map<std::string, bool> fcl_capped;    // ISO 9920's estimate stopped at kFclEstimateMaxIcl_clo
    std::map<std::string, std::pair<double, double>> fcl_span;  // capped: fcl at the cap and ISO 9920's own
};

double mean_of(const std::vector<double>& v) {
    double s = 0.0;
    int n = 0;
    for (double x : v)
        if (std::isfinite(x)) {
            s += x;
            ++n;
        }
    return n > 0 ? s / n : kNaN;
}

Quantities evaluate(const std::vector<TestTrial>& trials, const ZoneMap& map, const std::set<std::string>& regions,
                    const std::map<std::string, std::optional<double>>& given_fcl, const Draw& d, double fabric_r_m2k_w = 0.0) {
    Quantities out;
    // Insulation first: the evaporative test's dry part needs each zone's It.
    std::map<std::string, std::vector<std::vector<double>>> zone_it;  // ensemble -> replicate -> zone
    for (const auto& t : trials) {
        if (t.test != "insulation") continue;
        const Perturbed p = perturb(t, d);
        const Weights w = weights(map, p);
        double ts = 0.0, q = 0.0, serial = 0.0;
        std::vector<double> it_z(map.zones.size(), kNaN);
        for (std::size_t i = 0; i < w.zones.size(); ++i) {
            const std::size_t z = w.zones[i];
            ts += w.f[i] * p.skin_c[z];
            q += w.f[i] * p.q_w_m2[z];
            it_z[z] = (p.skin_c[z] - p.air_temp_c) / p.q_w_m2[z];
            serial += w.f[i] * it_z[z];
        }
        auto& rep = out.replicates[t.ensemble];
        rep["It_par"].push_back((ts - p.air_temp_c) / q);   // ASTM F1291 / ISO 15831, parallel
        rep["It_ser"].push_back(serial);                     // serial
        for (const auto& region : regions) {
            const Weights wr = weights(map, p, region);
            double tr = 0.0, qr = 0.0;
            for (std::size_t i = 0; i < wr.zones.size(); ++i) {
                tr += wr.f[i] * p.skin_c[wr.zones[i]];
                qr += wr.f[i] * p.q_w_m2[wr.zones[i]];
            }
            rep["It_par:" + region].push_back(wr.zones.empty() ? kNaN : (tr - p.air_temp_c) / qr);
        }
        zone_it[t.ensemble].push_back(std::move(it_z));
    }
    for (const auto& t : trials) {
        if (t.test != "evaporative") continue;
        const Perturbed p = perturb(t, d);
        const Weights w = weights(map, p);
        // IAPWS's saturation pressure, not the twin's seed formula (0.39 % low at 35 °C: issue 63).
        const double p_air_kpa = p.air_rh_pct / 100.0 * physics::saturation_vapour_pressure_iapws_pa(p.air_temp_c) / 1000.0;
        // The dry part of each zone's loss (ASTM F2370, non-isothermal option): (T_z - T_a)/It_z
        // with the ensemble's own It per zone; none in the isothermal test (T_z = T_a).
        std::vector<double> it_z(map.zones.size(), kNaN);
        if (const auto it = zone_it.find(t.ensemble); it != zone_it.end())
            for (std::size_t z = 0; z < it_z.size(); ++z) {
                std::vector<double> v;
                for (const auto& rep : it->second) v.push_back(rep[z]);
                it_z[z] = mean_of(v);
            }
        double ps = 0.0, qe = 0.0, serial = 0.0;
        std::vector<double> qe_z(map.zones.size(), kNaN), ps_z(map.zones.size(), kNaN);
        for (std::size_t i = 0; i < w.zones.size(); ++i) {
            const std::size_t z = w.zones[i];
            const double dry = std::isfinite(it_z[z]) && it_z[z] > 0.0 ? (p.skin_c[z] - p.air_temp_c) / it_z[z] : 0.0;
            qe_z[z] = p.q_w_m2[z] - dry;
            // The wet fabric's surface, where the water evaporates, is below the sensor by q R_fabric
            // (the total flux through the skin fabric's resistance; 0: the sensor's temperature).
            ps_z[z] = physics::saturation_vapour_pressure_iapws_pa(p.skin_c[z] - p.q_w_m2[z] * fabric_r_m2k_w) / 1000.0;
            ps += w.f[i] * ps_z[z];
            qe += w.f[i] * qe_z[z];
            serial += w.f[i] * (ps_z[z] - p_air_kpa) / qe_z[z];
        }
        auto& rep = out.replicates[t.ensemble];
        rep["Ret_par"].push_back((ps - p_air_kpa) / qe);   // ASTM F2370, parallel (m²kPa/W)
        rep["Ret_ser"].push_back(serial);
        for (const auto& region : regions) {
            const Weights wr = weights(map, p, region);
            double pr = 0.0, qr = 0.0;
            for (std::size_t i = 0; i < wr.zones.size(); ++i) {
                pr += wr.f[i] * ps_z[wr.zones[i]];
                qr += wr.f[i] * qe_z[wr.zones[i]];
            }
            rep["Ret_par:" + region].push_back(wr.zones.empty() ? kNaN : (pr - p_air_kpa) / qr);
        }
    }
    for (const auto& [ensemble, keys] : out.replicates)
        for (const auto& [key, v] : keys) out.value[ensemble][key] = mean_of(v);
    // Derived from the nude manikin's values (ISO 9920 4.2).
    const auto nude = out.value.find("nude");
    for (auto& [ensemble, v] : out.value) {
        auto get = [&](const std::map<std::string, double>& m, const std::string& k) {
            const auto it = m.find(k);
            return it == m.end() ? kNaN : it->second;
        };
        const double it = get(v, "It_par"), ret = get(v, "Ret_par");
        if (std::isfinite(it) && std::isfinite(ret)) v["im"] = it / (kLewisRelation_k_kpa * ret);
        if (ensemble == "nude" || nude == out.value.end()) continue;
        const double ia = get(nude->second, "It_par"), rea = get(nude->second, "Ret_par");
        // No fcl source (not given, no It or no Ia to estimate it from): NaN, and nothing that
        // needs fcl is computed; an assumed 1.0 would put Recl 10-13 % low unsaid.
        double fcl = kNaN;
        const auto given = given_fcl.find(ensemble);
        if (given != given_fcl.end() && given->second) {
            fcl = *given->second;
        } else if (std::isfinite(it) && std::isfinite(ia)) {
            // ISO 9920's estimate fcl = 1.00 + 0.28 Icl (Icl in clo), with Icl = It - Ia/fcl: a
            // fixed point that converges in a few steps (the map contracts: 0.28 Ia/0.155 fcl² < 1;
            // the cap at 2 clo only flattens it).
            auto fixed_point = [&](double cap_clo) {
                double f = 1.0, icl_clo = 0.0;
                for (int i = 0; i < 20; ++i) {
                    icl_clo = std::max(0.0, it - ia / f) / kClo_m2k_w;
                    f = 1.0 + 0.28 * std::min(icl_clo, cap_clo);
                }
                return std::make_pair(f, icl_clo);
            };
            const auto [capped_fcl, icl_clo] = fixed_point(kFclEstimateMaxIcl_clo);
            fcl = capped_fcl;
            out.fcl_capped[ensemble] = icl_clo > kFclEstimateMaxIcl_clo;
            if (out.fcl_capped[ensemble]) {
                // Beyond 2 clo the true fcl lies between the cap's value and ISO 9920's own
                // (which overestimates there): the middle, rectangular over that span (GUM 4.3.7;
                // issue 63's parka, fcl 2.07 by ISO 9920, was 2.3 % low in Icl at the cap).
                const double iso_fcl = fixed_point(std::numeric_limits<double>::infinity()).first;
                fcl = 0.5 * (capped_fcl + iso_fcl);
                out.fcl_span[ensemble] = {capped_fcl, iso_fcl};
            }
        }
        out.fcl[ensemble] = fcl;
        if (std::isfinite(it) && std::isfinite(ia)) {
            v["Icle_par"] = it - ia;
            if (std::isfinite(fcl)) v["Icl_par"] = it - ia / fcl;
            for (const auto& region : regions) {
                const double a = get(v, "It_par:" + region), b = get(nude->second, "It_par:" + region);
                if (std::isfinite(a) && std::isfinite(b)) v["Icle_par:" + region] = a - b;
            }
        }
        if (std::isfinite(ret) && std::isfinite(rea) && std::isfinite(fcl)) v["Recl_par"] = ret - rea / fcl;
    }
    return out;
}

double t_quantile(double dof, double p) {
    if (!(dof > 0.0) || !std::isfinite(dof) || dof > 1e6) return boost::math::quantile(boost::math::students_t(1e6), p);
    return boost::math::quantile(boost::math::students_t(dof), p);
}

// Type A of a mean of replicates: s / sqrt(n) on n - 1 dof.
struct TypeA {
    double u = kNaN;
    double dof = 0.0;
};
TypeA type_a(const std::vector<double>& v) {
    std::vector<double> x;
    for (double a : v)
        if (std::isfinite(a)) x.push_back(a);
    if (x.size() < 2) return {};
    const double m = std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(x.size());
    double ss = 0.0;
    for (double a : x) ss += (a - m) * (a - m);
    const double n = static_cast<double>(x.size());
    return {std::sqrt(ss / (n - 1.0) / n), n - 1.0};
}

// A sum of independent Type A parts c_i u_i (Welch-Satterthwaite dof).
TypeA combine(const std::vector<std::pair<double, TypeA>>& parts) {
    // A part without Type A (one replicate, nothing carried) adds none; the others' stays (issue
    // 63: a 1-replicate nude took the 3-replicate ensemble's scatter out of Icle, Icl and Recl).
    double var = 0.0, denom = 0.0;
    bool any = false;
    for (const auto& [c, a] : parts) {
        if (!std::isfinite(a.u)) continue;
        any = true;
        const double v = c * c * a.u * a.u;
        var += v;
        denom += a.dof > 0.0 ? v * v / a.dof : 0.0;
    }
    if (!any) return {};
    TypeA out;
    out.u = std::sqrt(var);
    out.dof = denom > 0.0 ? var * var / denom : 1e9;
    return out;
}

Value make_value(double value, TypeA a, double u_b, const std::string& unit, double confidence) {
    Value v;
    v.value = value;
    v.unit = unit;
    v.u_a = a.u;
    v.u_b = u_b;
    const double ua = std::isfinite(a.u) ? a.u : 0.0;
    v.u_c = std::hypot(ua, u_b);
    // GUM G.4.1: only the Type A part has finite degrees of freedom.
    v.dof = ua > 0.0 ? std::pow(v.u_c, 4) / (std::pow(ua, 4) / a.dof) : 1e9;
    v.k = std::isfinite(a.u) ? t_quantile(v.dof, 0.5 + confidence / 2.0) : 2.0;
    v.U95 = v.k * v.u_c;
    return v;
}

Conditions conditions_of(const std::vector<TestTrial>& trials, const std::string& ensemble, const std::string& test) {
    Conditions c;
    std::vector<double> ta, rh, v, ts;
    for (const auto& t : trials)
        if (t.ensemble == ensemble && t.test == test) {
            ta.push_back(t.r->air_temp_c);
            rh.push_back(t.r->air_rh_pct);
            v.push_back(t.r->air_speed_m_s);
            ts.push_back(t.r->mean_skin_temp_c);
            ++c.trials;
        }
    c.air_temp_c = mean_of(ta);
    c.air_rh_pct = mean_of(rh);
    c.air_speed_m_s = mean_of(v);
    c.mean_skin_temp_c = mean_of(ts);
    return c;
}

std::optional<double> cv_of(const std::vector<double>& v) {
    const TypeA a = type_a(v);
    if (!std::isfinite(a.u)) return std::nullopt;
    const double m = mean_of(v);
    return a.u * std::sqrt(static_cast<double>(v.size())) / std::abs(m);
}

// The standards' conditions (docs/clothing.md, "Acceptance and conditions"). Where a public
// summary gives a set point but no tolerance, the tolerance is ours and the source says so.
constexpr double kSkinTolerance_k = 0.5;       // ours
constexpr double kEvaporativeRhTolerance_pct = 5.0;  // ours

Check make_check(std::string quantity, std::string requirement, double value, std::string unit, std::optional<bool> pass,
                 std::string source) {
    Check c{std::move(quantity), std::move(requirement), value, std::move(unit), "", std::move(source)};
    c.status = !std::isfinite(value) ? "not recorded" : !pass ? "not applicable" : *pass ? "pass" : "out of range";
    return c;
}

std::vector<Check> insulation_checks(const Conditions& c) {
    const double skin = c.mean_skin_temp_c, gap = c.mean_skin_temp_c - c.air_temp_c;
    const bool astm = std::abs(skin - 35.0) <= kSkinTolerance_k, iso = std::abs(skin - 34.0) <= kSkinTolerance_k;
    return {
        make_check("mean skin temperature", "35 ± 0.5 °C (ASTM F1291) or 34 ± 0.5 °C (ISO 15831)", skin, "°C", astm || iso,
                   "ASTM F1291, ISO 15831 set points; the ±0.5 K is ours"),
        make_check("air below mean skin", "at least 12 K", gap, "K", gap >= 12.0, "ASTM F1291, ISO 15831"),
        make_check("relative humidity", "30-70 %", c.air_rh_pct, "%", c.air_rh_pct >= 30.0 && c.air_rh_pct <= 70.0, "ASTM F1291"),
        make_check("air speed", "0.4 ± 0.1 m/s", c.air_speed_m_s, "m/s", std::abs(c.air_speed_m_s - 0.4) <= 0.1,
                   "ASTM F1291, ISO 15831 (0.4 m/s)"),
    };
}

std::vector<Check> evaporative_checks(const Conditions& c, bool own_it) {
    const double skin = c.mean_skin_temp_c, gap = c.mean_skin_temp_c - c.air_temp_c;
    const bool isothermal = std::abs(gap) <= kIsothermalTolerance_k;
    return {
        make_check("mean skin temperature", "35 ± 0.5 °C", skin, "°C", std::abs(skin - 35.0) <= kSkinTolerance_k,
                   "ASTM F2370 set point; the ±0.5 K is ours"),
        make_check("skin - air", "within ±0.5 K (isothermal), else the non-isothermal option with the ensemble's insulation test", gap,
                   "K", isothermal || own_it, "ASTM F2370; the 0.5 K is ours"),
        make_check("relative humidity", "40 ± 5 % in the isothermal test", c.air_rh_pct, "%",
                   isothermal ? std::optional<bool>(std::abs(c.air_rh_pct - 40.0) <= kEvaporativeRhTolerance_pct) : std::nullopt,
                   "ASTM F2370 set point; the ±5 % is ours"),
        make_check("air speed", "0.4 ± 0.1 m/s", c.air_speed_m_s, "m/s", std::abs(c.air_speed_m_s - 0.4) <= 0.1, "ASTM F2370"),
    };
}

std::string check_value(const Check& c) {
    if (!std::isfinite(c.value)) return "not recorded";
    const int digits = c.unit == "%" ? 0 : c.unit == "m/s" || c.unit == "K" ? 2 : 1;
    return fmt::format("{:.{}f} {}", c.value, digits, c.unit);
}

}  // namespace

Result compute(const Campaign& campaign, const CampaignResult& analysis, const Campaign* baseline,
               const CampaignResult* baseline_analysis, const Options& options) {
    Result out;
    out.campaign = campaign.name;
    out.standards = campaign.standards;
    out.options = options;
    auto collect = [&](const Campaign& c, const CampaignResult& a, std::vector<TestTrial>& into, bool nude_only) {
        std::map<std::string, const TrialResult*> by_id;
        for (const auto& cs : a.cases)
            for (const auto& t : cs.trials) by_id[t.id] = &t;
        for (const auto& cs : a.unanalysed_cases)
            for (const auto& t : cs.trials) by_id[t.id] = &t;
        for (const auto& trial : c.trials) {
            const auto& info = trial.info;
            if (info.ensemble.empty() || info.test.empty()) continue;
            if (nude_only && info.ensemble != "nude") continue;
            const auto it = by_id.find(info.id);
            if (it == by_id.end() || !it->second->included) {
                const std::string why = it == by_id.end() ? "not analysed" : it->second->exclusion_reason;
                out.warnings.push_back(fmt::format("{}: trial {} ({} {}) left out: {}", c.name, info.id, info.ensemble, info.test, why));
                out.left_out.push_back({info.id, info.ensemble, info.test, why});
                continue;
            }
            into.push_back({info.ensemble, info.test, info.id, it->second, &c});
        }
    };
    std::vector<TestTrial> trials;
    collect(campaign, analysis, trials, false);
    const bool own_nude = std::any_of(trials.begin(), trials.end(), [](const auto& t) { return t.ensemble == "nude"; });
    if (baseline && baseline_analysis) {
        if (own_nude) {
            out.warnings.push_back("the campaign has its own nude trials: --baseline is not used");
        } else {
            const auto before = trials.size();
            collect(*baseline, *baseline_analysis, trials, true);
            if (trials.size() == before)
                throw std::invalid_argument(fmt::format("--baseline {}: no steady nude trial (ensemble \"nude\" with a test)", baseline->name));
            out.baseline = baseline->name;
        }
    }
    if (trials.empty())
        throw std::invalid_argument(fmt::format(
            "{}: no clothing test in this campaign (no trial names an ensemble and a test; docs/clothing.md)", campaign.name));

    const ZoneMap& map = campaign.zone_map;
    std::set<std::string> regions;
    for (const auto& z : map.zones) regions.insert(z.region);
    std::map<std::string, std::optional<double>> given_fcl, given_fcl_u;
    for (const auto& [id, e] : campaign.ensembles) given_fcl[id] = e.fcl, given_fcl_u[id] = e.fcl_u;

    const Quantities measured = evaluate(trials, map, regions, given_fcl, Draw{}, options.fabric_resistance_m2k_w);
    // Monte Carlo over the shared instrument errors (GUM Supplement 1): the Type B standard
    // uncertainty of every quantity is its standard deviation over the draws.
    std::mt19937_64 rng(options.seed);
    const auto dist = [&](const char* ch) { return campaign.instrument(ch).distribution; };
    std::map<std::string, std::map<std::string, std::pair<double, double>>> sums;  // sum, sum of squares
    const int draws = std::max(100, options.monte_carlo_draws);
    for (int i = 0; i < draws; ++i) {
        Draw d;
        d.flux_offset = standardised_error_draw(dist("heat_flux_w_m2"), rng);
        d.flux_gain = standardised_error_draw(dist("heat_flux_w_m2"), rng);
        d.air = standardised_error_draw(dist("air_temp_c"), rng);
        d.skin = standardised_error_draw(dist("skin_temp_c"), rng);
        d.rh = standardised_error_draw(dist("air_rh_pct"), rng);
        const Quantities q = evaluate(trials, map, regions, given_fcl, d, options.fabric_resistance_m2k_w);
        for (const auto& [ensemble, keys] : q.value)
            for (const auto& [key, v] : keys) {
                if (!std::isfinite(v)) continue;
                const auto base = measured.value.at(ensemble).count(key) ? measured.value.at(ensemble).at(key) : kNaN;
                auto& s = sums[ensemble][key];
                s.first += v - base;
                s.second += (v - base) * (v - base);
            }
    }
    auto u_b = [&](const std::string& ensemble, const std::string& key) {
        const auto& s = sums[ensemble][key];
        const double n = static_cast<double>(draws);
        return std::sqrt(std::max(0.0, s.second / n - (s.first / n) * (s.first / n)));
    };

    std::vector<std::string> order;
    if (measured.value.count("nude")) order.push_back("nude");
    for (const auto& [id, v] : measured.value)
        if (id != "nude") order.push_back(id);
    bool nude_ret_withheld = false;  // "nude" comes first: its Rea feeds every Recl
    for (const auto& id : order) {
        const auto& v = measured.value.at(id);
        const auto& reps = measured.replicates.at(id);
        auto value_of = [&](const std::string& k) {
            const auto it = v.find(k);
            return it == v.end() ? kNaN : it->second;
        };
        auto reps_of = [&](const std::string& k) {
            const auto it = reps.find(k);
            return it == reps.end() ? std::vector<double>{} : it->second;
        };
        // Type A of a key: from the replicates, or at one replicate from the carried scatter.
        auto type_a_in = [&](const std::string& ensemble, const std::string& k) {
            const auto it = measured.replicates.find(ensemble);
            if (it == measured.replicates.end() || !it->second.count(k)) return TypeA{};
            const auto& values = it->second.at(k);
            const TypeA own = type_a(values);
            if (std::isfinite(own.u) || !options.redressing) return own;
            const auto& carried = ensemble == "nude" ? options.redressing->nude : options.redressing->dressed;
            const auto c = carried.find(k);
            const double m = mean_of(values);
            if (c == carried.end() || !std::isfinite(m) || values.empty()) return TypeA{};
            return TypeA{std::abs(m) * c->second.first / std::sqrt(static_cast<double>(values.size())), c->second.second};
        };
        auto nude_a = [&](const std::string& k) { return type_a_in("nude", k); };
        auto own_a = [&](const std::string& k) { return type_a_in(id, k); };
        EnsembleResult e;
        e.id = id;
        if (const auto it = campaign.ensembles.find(id); it != campaign.ensembles.end()) e.description = it->second.description;
        const double ia = measured.value.count("nude") && measured.value.at("nude").count("It_par")
                              ? measured.value.at("nude").at("It_par") : kNaN;
        const double rea = measured.value.count("nude") && measured.value.at("nude").count("Ret_par")
                               ? measured.value.at("nude").at("Ret_par") : kNaN;
        if (id == "nude") {
            e.description = e.description.empty() ? "the bare manikin" : e.description;
            e.fcl = 1.0;
            e.fcl_source = "nude";
            e.fcl_reason = "the bare manikin";
        } else if (given_fcl.count(id) && given_fcl.at(id)) {
            e.fcl = *given_fcl.at(id);
            e.fcl_source = "given";
            if (given_fcl_u.count(id) && given_fcl_u.at(id)) {
                e.fcl_u = *given_fcl_u.at(id);
                e.fcl_reason = fmt::format("given in campaign.json (measured by the lab), u(fcl) = {:.3g} in U of Icl and Recl", e.fcl_u);
            } else {
                e.fcl_reason = "given in campaign.json (measured by the lab) without fcl_u: its uncertainty is left out of U of "
                               "Icl and Recl (give ensembles.<id>.fcl_u)";
            }
        } else if (measured.fcl.count(id) && std::isfinite(measured.fcl.at(id))) {
            e.fcl = measured.fcl.at(id);
            e.fcl_source = "ISO 9920 estimate";
            e.fcl_capped = measured.fcl_capped.count(id) && measured.fcl_capped.at(id);
            e.fcl_u = kFclEstimateU;
            if (e.fcl_capped && measured.fcl_span.count(id)) {
                const auto [lo, hi] = measured.fcl_span.at(id);
                e.fcl_u = std::max(kFclEstimateCappedU, (hi - lo) / std::sqrt(12.0));  // rectangular over [lo, hi]
                e.fcl_reason = fmt::format(
                    "ISO 9920 estimate 1.00 + 0.28 Icl (clo) beyond its range: between {:.2f} (capped at Icl = {:.0f} clo, where the "
                    "estimate is for ordinary ensembles) and {:.2f} (ISO 9920's own, which overestimates above it), the middle with "
                    "u(fcl) = {:.2f} (rectangular over that span); measure fcl for a heavy ensemble",
                    lo, kFclEstimateMaxIcl_clo, hi, e.fcl_u);
            } else {
                e.fcl_reason = fmt::format("ISO 9920 estimate 1.00 + 0.28 Icl (clo) from this ensemble's It; u(fcl) = {:.2f}", e.fcl_u);
            }
        } else {
            e.fcl_source = "none";
            e.fcl_reason = !std::isfinite(value_of("It_par"))
                               ? "not given in campaign.json and no insulation test of the ensemble to estimate it from"
                               : "not given in campaign.json and no nude insulation test to estimate it from";
        }
        const double conf = options.confidence;
        // An estimated fcl's own uncertainty (the regression's, independent of the instruments)
        // joins Type B: Icl = It - Ia/fcl and Recl = Ret - Rea/fcl move by Ia/fcl² and Rea/fcl² per unit fcl.
        auto with_fcl = [&](double ub, double nude_value) {
            return e.fcl_u > 0.0 && std::isfinite(nude_value) ? std::hypot(ub, nude_value / (e.fcl * e.fcl) * e.fcl_u) : ub;
        };
        if (std::isfinite(value_of("It_par"))) {
            e.insulation_conditions = conditions_of(trials, id, "insulation");
            e.insulation_replicates = reps_of("It_par");
            e.insulation_total_parallel = make_value(value_of("It_par"), own_a("It_par"), u_b(id, "It_par"), "m2K/W", conf);
            e.insulation_total_serial = make_value(value_of("It_ser"), own_a("It_ser"), u_b(id, "It_ser"), "m2K/W", conf);
            e.insulation_cv = cv_of(e.insulation_replicates);
            if (e.insulation_cv) e.insulation_cv_pass = *e.insulation_cv <= options.cv_limit_insulation;
            if (std::isfinite(value_of("Icle_par"))) {
                const TypeA it_a = own_a("It_par"), ia_a = nude_a("It_par");
                e.insulation_effective_parallel =
                    make_value(value_of("Icle_par"), combine({{1.0, it_a}, {1.0, ia_a}}), u_b(id, "Icle_par"), "m2K/W", conf);
                if (std::isfinite(value_of("Icl_par")))
                    e.insulation_intrinsic_parallel = make_value(value_of("Icl_par"), combine({{1.0, it_a}, {1.0 / e.fcl, ia_a}}),
                                                                 with_fcl(u_b(id, "Icl_par"), ia), "m2K/W", conf);
            }
        }
        bool ret_withheld = false;
        if (std::isfinite(value_of("Ret_par"))) {
            e.evaporative_conditions = conditions_of(trials, id, "evaporative");
            const auto& c = *e.evaporative_conditions;
            const double gap = c.mean_skin_temp_c - c.air_temp_c;
            const bool isothermal = std::abs(gap) <= kIsothermalTolerance_k;
            const bool own_it = e.insulation_total_parallel.has_value();
            // With the ensemble's It the dry part (T_z - T_a)/It_z is always removed, inside the
            // tolerance too; without it, a gap inside the tolerance is reported with its bias
            // bound and a gap beyond it withholds Ret (the measured flux is not evaporative alone).
            e.evaporative_method =
                fmt::format("{} (skin - air {:+.2f} K, tolerance {:.1f} K): {}", isothermal ? "isothermal" : "non-isothermal", gap,
                            kIsothermalTolerance_k,
                            own_it ? "dry part removed with the ensemble's It per zone"
                                   : "dry part not removed (no insulation test of the ensemble)");
            if (!isothermal && !own_it) {
                ret_withheld = true;
                e.evaporative_withheld_reason = fmt::format(
                    "skin - air {:+.2f} K is beyond the isothermal tolerance {:.1f} K and the ensemble has no insulation test: "
                    "the measured heat loss includes dry heat that cannot be removed, so Ret is not a result (run the "
                    "insulation test of the ensemble too, or the wet test isothermal)",
                    gap, kIsothermalTolerance_k);
                out.warnings.push_back(fmt::format("{}: Ret withheld: {}", id, e.evaporative_withheld_reason));
            } else if (!own_it && gap != 0.0) {
                const double dp_kpa = (physics::saturation_vapour_pressure_iapws_pa(c.mean_skin_temp_c) -
                                       c.air_rh_pct / 100.0 * physics::saturation_vapour_pressure_iapws_pa(c.air_temp_c)) / 1000.0;
                // Ret_measured / Ret - 1 = -(gap/It) Ret_measured / dp; It >= Ia bounds it.
                if (std::isfinite(ia) && ia > 0.0 && dp_kpa > 0.0) {
                    e.evaporative_dry_bias_bound = -gap / ia * value_of("Ret_par") / dp_kpa;
                    out.warnings.push_back(fmt::format(
                        "{}: evaporative test isothermal within {:.1f} K (skin - air {:+.2f} K) without an insulation test of "
                        "the ensemble: the dry heat stays in Ret, which is up to {:.1f} % {} (bound from the nude Ia; not in U)",
                        id, kIsothermalTolerance_k, gap, 100.0 * std::abs(*e.evaporative_dry_bias_bound),
                        gap > 0.0 ? "low" : "high"));
                } else {
                    e.evaporative_dry_bias_bound = kNaN;
                    out.warnings.push_back(fmt::format(
                        "{}: evaporative test isothermal within {:.1f} K (skin - air {:+.2f} K) without an insulation test of "
                        "the ensemble or of the nude manikin: the dry heat stays in Ret, by an amount not estimable here",
                        id, kIsothermalTolerance_k, gap));
                }
            }
            if (!ret_withheld) {
                e.evaporative_replicates = reps_of("Ret_par");
                e.evaporative_total_parallel = make_value(value_of("Ret_par"), own_a("Ret_par"), u_b(id, "Ret_par"), "m2kPa/W", conf);
                e.evaporative_total_serial = make_value(value_of("Ret_ser"), own_a("Ret_ser"), u_b(id, "Ret_ser"), "m2kPa/W", conf);
                e.evaporative_cv = cv_of(e.evaporative_replicates);
                if (e.evaporative_cv) e.evaporative_cv_pass = *e.evaporative_cv <= options.cv_limit_evaporative;
            }
            if (id == "nude") nude_ret_withheld = ret_withheld;
            const bool nude_ret = std::isfinite(rea) && !nude_ret_withheld;
            if (id != "nude" && !ret_withheld && nude_ret) {
                if (std::isfinite(value_of("Recl_par")))
                    e.evaporative_intrinsic_parallel =
                        make_value(value_of("Recl_par"), combine({{1.0, own_a("Ret_par")}, {1.0 / e.fcl, nude_a("Ret_par")}}),
                                   with_fcl(u_b(id, "Recl_par"), rea), "m2kPa/W", conf);
                else
                    e.intrinsic_evaporative_withheld_reason = "Recl = Ret - Rea/fcl needs fcl: " + e.fcl_reason +
                                                              " (give the measured fcl in campaign.json `ensembles`)";
            } else if (id != "nude" && !ret_withheld && std::isfinite(rea) && nude_ret_withheld) {
                e.intrinsic_evaporative_withheld_reason = "the nude manikin's Rea is withheld (see its entry)";
            }
        }
        if (std::isfinite(value_of("im")) && !ret_withheld) {
            const double it = value_of("It_par"), ret = value_of("Ret_par");
            const TypeA a = combine({{value_of("im") / it, own_a("It_par")}, {value_of("im") / ret, own_a("Ret_par")}});
            e.permeability_index = make_value(value_of("im"), a, u_b(id, "im"), "1", conf);
        }
        for (const auto& region : regions) {
            RegionValues rv;
            rv.region = region;
            for (const auto& z : map.zones)
                if (z.region == region) rv.area_m2 += z.area_m2;
            if (std::isfinite(value_of("It_par:" + region)))
                rv.insulation_total = make_value(value_of("It_par:" + region), own_a("It_par:" + region),
                                                 u_b(id, "It_par:" + region), "m2K/W", conf);
            if (std::isfinite(value_of("Icle_par:" + region)))
                rv.insulation_effective = make_value(value_of("Icle_par:" + region),
                                                     combine({{1.0, own_a("It_par:" + region)}, {1.0, nude_a("It_par:" + region)}}),
                                                     u_b(id, "Icle_par:" + region), "m2K/W", conf);
            if (std::isfinite(value_of("Ret_par:" + region)) && !ret_withheld)
                rv.evaporative_total = make_value(value_of("Ret_par:" + region), own_a("Ret_par:" + region),
                                                  u_b(id, "Ret_par:" + region), "m2kPa/W", conf);
            if (rv.insulation_total || rv.evaporative_total) e.regions.push_back(std::move(rv));
        }
        if (id != "nude" && !measured.value.count("nude"))
            e.notes.push_back("no nude trials (here or --baseline): effective and intrinsic values need Ia and Rea");
        if (e.insulation_replicates.size() == 1 || e.evaporative_replicates.size() == 1) {
            if (options.redressing) {
                const auto& carried = id == "nude" ? options.redressing->nude : options.redressing->dressed;
                std::string what;
                for (const char* k : {"It_par", "Ret_par"})
                    if (const auto c = carried.find(k); c != carried.end())
                        what += fmt::format("{}{} {:.1f} % on {:.0f} dof", what.empty() ? "" : ", ", k, 100.0 * c->second.first, c->second.second);
                e.notes.push_back(fmt::format("one replicate: Type A is the re-dressing scatter carried from {} ({}); no replicate "
                                              "criterion", options.redressing->source, what.empty() ? "none for these quantities" : what));
            } else {
                e.notes.push_back("one replicate: the interval excludes re-dressing (U from the instruments alone, k = 2), so "
                                  "it is too short for a garment dressed again; carry the lab's scatter from a test with "
                                  "replicates (--redress-from <campaign>); no replicate criterion");
            }
        }
        if (e.insulation_conditions) e.insulation_checks = insulation_checks(*e.insulation_conditions);
        if (e.evaporative_conditions)
            e.evaporative_checks = evaporative_checks(*e.evaporative_conditions, e.insulation_total_parallel.has_value());
        out.ensembles.push_back(std::move(e));
    }
    out.replicates = measured.replicates;
    std::set<std::string> named;
    for (const auto& [id, e] : campaign.ensembles) named.insert(id);
    for (const auto& l : out.left_out) named.insert(l.ensemble);
    for (const auto& id : named)
        if (std::none_of(out.ensembles.begin(), out.ensembles.end(), [&](const EnsembleResult& e) { return e.id == id; }))
            out.without_result.push_back(id);
    // Conditions against the standards: every check is in the result; those out of range are
    // warnings as well, never a refusal (a lab may test otherwise on purpose).
    for (const auto& e : out.ensembles)
        for (const auto* checks : {&e.insulation_checks, &e.evaporative_checks})
            for (const auto& c : *checks)
                if (c.status == "out of range")
                    out.warnings.push_back(fmt::format("{}: {} test: {} {} out of range ({}; {})", e.id,
                                                       checks == &e.insulation_checks ? "insulation" : "evaporative", c.quantity,
                                                       check_value(c), c.requirement, c.source));
    return out;
}

namespace {

nlohmann::json value_json(const std::optional<Value>& v) {
    if (!v) return nullptr;
    return {{"value", v->value}, {"U95", v->U95}, {"unit", v->unit}, {"u_a", std::isfinite(v->u_a) ? nlohmann::json(v->u_a) : nlohmann::json()},
            {"u_b", v->u_b}, {"u_c", v->u_c}, {"k", v->k}, {"dof", v->dof > 1e8 ? nlohmann::json() : nlohmann::json(v->dof)},
            {"clo", v->unit == "m2K/W" ? nlohmann::json(v->value / kClo_m2k_w) : nlohmann::json()},
            {"U95_clo", v->unit == "m2K/W" ? nlohmann::json(v->U95 / kClo_m2k_w) : nlohmann::json()},
            {"value_m2pa_w", v->unit == "m2kPa/W" ? nlohmann::json(v->value * 1000.0) : nlohmann::json()},
            {"U95_m2pa_w", v->unit == "m2kPa/W" ? nlohmann::json(v->U95 * 1000.0) : nlohmann::json()}};
}

nlohmann::json conditions_json(const std::optional<Conditions>& c) {
    if (!c) return nullptr;
    auto num = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(); };
    return {{"air_temp_c", num(c->air_temp_c)}, {"air_rh_pct", num(c->air_rh_pct)}, {"air_speed_m_s", num(c->air_speed_m_s)},
            {"mean_skin_temp_c", num(c->mean_skin_temp_c)}, {"trials", c->trials}};
}

nlohmann::json checks_json(const std::vector<Check>& checks) {
    nlohmann::json a = nlohmann::json::array();
    for (const auto& c : checks)
        a.push_back({{"quantity", c.quantity}, {"requirement", c.requirement},
                     {"value", std::isfinite(c.value) ? nlohmann::json(c.value) : nlohmann::json()}, {"unit", c.unit},
                     {"status", c.status}, {"source", c.source}});
    return a;
}

nlohmann::json text_or_null(const std::string& s) { return s.empty() ? nlohmann::json() : nlohmann::json(s); }

void checks_text(std::ostringstream& o, const std::vector<Check>& checks) {
    for (const auto& c : checks)
        o << fmt::format("    check {} {}: {} ({}; {})\n", c.quantity, check_value(c),
                         c.status == "out of range" ? "OUT OF RANGE" : c.status, c.requirement, c.source);
}

std::string fmt_value(const std::optional<Value>& v, bool clo = false) {
    if (!v) return "-";
    if (clo) return fmt::format("{:.4f} ± {:.4f} m²K/W ({:.3f} ± {:.3f} clo)", v->value, v->U95, v->value / kClo_m2k_w, v->U95 / kClo_m2k_w);
    if (v->unit == "m2kPa/W") return fmt::format("{:.4f} ± {:.4f} m²kPa/W ({:.1f} ± {:.1f} m²Pa/W)", v->value, v->U95, 1000 * v->value, 1000 * v->U95);
    return fmt::format("{:.3f} ± {:.3f}", v->value, v->U95);
}

}  // namespace

RedressingScatter redressing_scatter(const Result& earlier) {
    // Pooled relative variance: sum (n_e - 1) cv_e^2 / sum (n_e - 1) over the ensembles.
    std::map<std::string, std::pair<double, double>> dressed_ss, nude_ss;  // key -> (sum (n-1) cv^2, sum (n-1))
    for (const auto& [ensemble, keys] : earlier.replicates)
        for (const auto& [key, values] : keys) {
            if (key.rfind("It_", 0) != 0 && key.rfind("Ret_", 0) != 0) continue;  // the measured totals
            const auto cv = cv_of(values);
            if (!cv) continue;
            std::size_t n = 0;
            for (double v : values) n += std::isfinite(v) ? 1 : 0;
            auto& s = (ensemble == "nude" ? nude_ss : dressed_ss)[key];
            s.first += static_cast<double>(n - 1) * *cv * *cv;
            s.second += static_cast<double>(n - 1);
        }
    RedressingScatter out;
    out.source = earlier.campaign;
    for (const auto& [key, s] : dressed_ss) out.dressed[key] = {std::sqrt(s.first / s.second), s.second};
    for (const auto& [key, s] : nude_ss) out.nude[key] = {std::sqrt(s.first / s.second), s.second};
    if (out.dressed.empty() && out.nude.empty())
        throw std::invalid_argument(fmt::format("{}: no ensemble has two replicates of a test, so it has no re-dressing "
                                                "scatter to carry", earlier.campaign));
    return out;
}

nlohmann::json to_json(const Result& r) {
    nlohmann::json j;
    j["campaign"] = r.campaign;
    j["baseline"] = r.baseline.empty() ? nlohmann::json() : nlohmann::json(r.baseline);
    j["standards"] = r.standards;  // {} when the campaign chose none
    if (r.options.redressing) {
        nlohmann::json carried = {{"source", r.options.redressing->source}};
        for (const auto& [name, m] : {std::pair{"dressed", &r.options.redressing->dressed}, std::pair{"nude", &r.options.redressing->nude}})
            for (const auto& [key, v] : *m) carried[name][key] = {{"relative_sd", v.first}, {"dof", v.second}};
        j["redressing_from"] = carried;
    } else {
        j["redressing_from"] = nullptr;
    }
    j["method"] = {{"insulation", "ASTM F1291 / ISO 15831: parallel (global) and serial; effective and intrinsic per ISO 9920"},
                   {"evaporative", r.options.fabric_resistance_m2k_w > 0.0
                                       ? fmt::format("ASTM F2370: parallel and serial, fully wet skin at the wet fabric's surface "
                                                     "(the sensor's temperature less q x {} m²K/W); IAPWS saturation pressure",
                                                     r.options.fabric_resistance_m2k_w)
                                       : std::string("ASTM F2370: parallel and serial, fully wet skin at the sensor's temperature "
                                                     "(no fabric resistance given: Ret may read high); IAPWS saturation pressure")},
                   {"type_a", r.options.redressing
                                  ? "re-dressed replicates: s/sqrt(n), n - 1 dof; at one replicate the re-dressing scatter carried from " +
                                        r.options.redressing->source
                                  : std::string("re-dressed replicates: s/sqrt(n), n - 1 dof; none at one replicate (the interval "
                                                "excludes re-dressing)")},
                   {"type_b", fmt::format("Monte Carlo over the instruments' shared errors, {} draws (GUM Supplement 1)",
                                          r.options.monte_carlo_draws)},
                   {"confidence", r.options.confidence},
                   {"cv_limit_insulation", r.options.cv_limit_insulation},
                   {"cv_limit_evaporative", r.options.cv_limit_evaporative},
                   {"lewis_relation_k_kpa", kLewisRelation_k_kpa},
                   {"clo_m2k_w", kClo_m2k_w}};
    j["left_out"] = nlohmann::json::array();
    for (const auto& l : r.left_out)
        j["left_out"].push_back({{"trial", l.trial}, {"ensemble", l.ensemble}, {"test", l.test}, {"reason", l.reason}});
    j["without_result"] = r.without_result;
    j["ensembles"] = nlohmann::json::array();
    for (const auto& e : r.ensembles) {
        nlohmann::json x;
        x["id"] = e.id;
        x["description"] = e.description;
        x["fcl"] = std::isfinite(e.fcl) ? nlohmann::json(e.fcl) : nlohmann::json();
        x["fcl_source"] = e.fcl_source;
        x["fcl_reason"] = e.fcl_reason;
        x["fcl_u"] = e.fcl_u > 0.0 ? nlohmann::json(e.fcl_u) : nlohmann::json();
        x["fcl_capped"] = e.fcl_capped;
        x["insulation"] = {{"total_parallel", value_json(e.insulation_total_parallel)},
                           {"total_serial", value_json(e.insulation_total_serial)},
                           {"effective_parallel", value_json(e.insulation_effective_parallel)},
                           {"intrinsic_parallel", value_json(e.insulation_intrinsic_parallel)},
                           {"replicates", e.insulation_replicates},
                           {"cv", e.insulation_cv ? nlohmann::json(*e.insulation_cv) : nlohmann::json()},
                           {"cv_pass", e.insulation_cv_pass ? nlohmann::json(*e.insulation_cv_pass) : nlohmann::json()},
                           {"conditions", conditions_json(e.insulation_conditions)},
                           {"checks", checks_json(e.insulation_checks)}};
        x["evaporative"] = {{"total_parallel", value_json(e.evaporative_total_parallel)},
                            {"total_serial", value_json(e.evaporative_total_serial)},
                            {"intrinsic_parallel", value_json(e.evaporative_intrinsic_parallel)},
                            {"replicates", e.evaporative_replicates},
                            {"cv", e.evaporative_cv ? nlohmann::json(*e.evaporative_cv) : nlohmann::json()},
                            {"cv_pass", e.evaporative_cv_pass ? nlohmann::json(*e.evaporative_cv_pass) : nlohmann::json()},
                            {"method", e.evaporative_method},
                            {"withheld_reason", text_or_null(e.evaporative_withheld_reason)},
                            {"intrinsic_withheld_reason", text_or_null(e.intrinsic_evaporative_withheld_reason)},
                            {"dry_bias_bound", e.evaporative_dry_bias_bound && std::isfinite(*e.evaporative_dry_bias_bound)
                                                   ? nlohmann::json(*e.evaporative_dry_bias_bound)
                                                   : nlohmann::json()},
                            {"conditions", conditions_json(e.evaporative_conditions)},
                            {"checks", checks_json(e.evaporative_checks)}};
        x["permeability_index"] = value_json(e.permeability_index);
        x["regions"] = nlohmann::json::array();
        for (const auto& rv : e.regions)
            x["regions"].push_back({{"region", rv.region}, {"area_m2", rv.area_m2},
                                    {"insulation_total_parallel", value_json(rv.insulation_total)},
                                    {"insulation_effective_parallel", value_json(rv.insulation_effective)},
                                    {"evaporative_total_parallel", value_json(rv.evaporative_total)}});
        x["notes"] = e.notes;
        j["ensembles"].push_back(x);
    }
    j["warnings"] = r.warnings;
    return j;
}

std::string to_text(const Result& r) {
    std::ostringstream o;
    o << fmt::format("Clothing tests: {}{}\n", r.campaign, r.baseline.empty() ? "" : " (nude baseline from " + r.baseline + ")");
    if (!r.standards.empty()) {  // as the campaign chose them ([standards])
        std::string followed;
        for (const auto& [test, standard] : r.standards) followed += (followed.empty() ? "" : "; ") + test + ": " + standard;
        o << "Standards followed: " << followed << "\n";
    }
    o << fmt::format("Values ± U95 ({:.0f} %: Type A from re-dressed replicates, Type B from the instruments by Monte Carlo)\n\n",
                     100.0 * r.options.confidence);
    for (const auto& e : r.ensembles) {
        o << fmt::format("{}{}{}\n", e.id, e.description.empty() ? "" : ": ", e.description);
        if (e.id != "nude")
            o << (std::isfinite(e.fcl) ? fmt::format("  fcl {:.3f}: {}\n", e.fcl, e.fcl_reason)
                                       : fmt::format("  fcl none: {}\n", e.fcl_reason));
        if (const auto& c = e.insulation_conditions)
            o << fmt::format("  insulation, {} trial{}: air {:.1f} °C, {:.0f} % RH, {:.2f} m/s, mean skin {:.1f} °C\n", c->trials,
                             c->trials == 1 ? "" : "s", c->air_temp_c, c->air_rh_pct, c->air_speed_m_s, c->mean_skin_temp_c);
        checks_text(o, e.insulation_checks);
        if (e.insulation_total_parallel) {
            o << "    It  total, parallel    " << fmt_value(e.insulation_total_parallel, true) << "\n";
            o << "    It  total, serial      " << fmt_value(e.insulation_total_serial, true) << "\n";
            if (e.insulation_effective_parallel) o << "    Icle effective         " << fmt_value(e.insulation_effective_parallel, true) << "\n";
            if (e.insulation_intrinsic_parallel) o << "    Icl intrinsic          " << fmt_value(e.insulation_intrinsic_parallel, true) << "\n";
            if (e.insulation_cv)
                o << fmt::format("    replicates {}: CV {:.1f} % (limit {:.0f} %): {}\n", e.insulation_replicates.size(), 100 * *e.insulation_cv,
                                 100 * r.options.cv_limit_insulation, *e.insulation_cv_pass ? "pass" : "FAIL");
        }
        if (const auto& c = e.evaporative_conditions)
            o << fmt::format("  evaporative ({}), {} trial{}: air {:.1f} °C, {:.0f} % RH, {:.2f} m/s, mean skin {:.1f} °C\n",
                             e.evaporative_method, c->trials, c->trials == 1 ? "" : "s", c->air_temp_c, c->air_rh_pct,
                             c->air_speed_m_s, c->mean_skin_temp_c);
        checks_text(o, e.evaporative_checks);
        if (!e.evaporative_withheld_reason.empty()) o << "    Ret withheld: " << e.evaporative_withheld_reason << "\n";
        if (e.evaporative_total_parallel) {
            o << "    Ret total, parallel    " << fmt_value(e.evaporative_total_parallel) << "\n";
            o << "    Ret total, serial      " << fmt_value(e.evaporative_total_serial) << "\n";
            if (e.evaporative_intrinsic_parallel) o << "    Recl intrinsic         " << fmt_value(e.evaporative_intrinsic_parallel) << "\n";
            if (!e.intrinsic_evaporative_withheld_reason.empty())
                o << "    Recl withheld: " << e.intrinsic_evaporative_withheld_reason << "\n";
            if (e.evaporative_dry_bias_bound && std::isfinite(*e.evaporative_dry_bias_bound))
                o << fmt::format("    dry heat left in Ret: up to {:.1f} % {} (not in U)\n", 100.0 * std::abs(*e.evaporative_dry_bias_bound),
                                 *e.evaporative_dry_bias_bound < 0.0 ? "low" : "high");
            if (e.evaporative_cv)
                o << fmt::format("    replicates {}: CV {:.1f} % (limit {:.0f} %): {}\n", e.evaporative_replicates.size(),
                                 100 * *e.evaporative_cv, 100 * r.options.cv_limit_evaporative, *e.evaporative_cv_pass ? "pass" : "FAIL");
        }
        if (e.permeability_index) o << "    im permeability index  " << fmt_value(e.permeability_index) << "\n";
        for (const auto& l : r.left_out)
            if (l.ensemble == e.id) o << fmt::format("  LEFT OUT: {} ({} test): {}\n", l.trial, l.test, l.reason);
        for (const auto& n : e.notes) o << "  note: " << n << "\n";
        o << "\n";
    }
    for (const auto& id : r.without_result) {
        o << fmt::format("{}: NO RESULT: every trial of it was left out\n", id);
        for (const auto& l : r.left_out)
            if (l.ensemble == id) o << fmt::format("  LEFT OUT: {} ({} test): {}\n", l.trial, l.test, l.reason);
        o << "\n";
    }
    for (const auto& w : r.warnings) o << "warning: " << w << "\n";
    return o.str();
}

}  // namespace manikind::analysis::clothing
