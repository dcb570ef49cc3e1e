#include "analysis/teq.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include <fmt/core.h>

#include "analysis/input_error.hpp"

namespace manikind::analysis::teq {
namespace {

constexpr double kInfinite = 1e9;

// Instrument errors of one Monte Carlo draw, in units of each spec's limit (a standardised draw
// from its distribution). skin and the flux's offset and gain are the manikin's, shared by the
// calibration and the measurement; air and wall are the chamber probes (calibration only);
// reference places the uniform enclosure's true temperature between air and wall.
struct Draw {
    double skin = 0.0, flux_offset = 0.0, flux_gain = 0.0, air = 0.0, wall = 0.0, reference = 0.0;
};

double perturbed_q(double q, const InstrumentSpec& flux, const Draw& d) {
    // The offset is the spec's fixed part, the gain its part of reading: a gain scales q, so it
    // keeps its sign for a zone that gains heat.
    return q * (1.0 + d.flux_gain * flux.accuracy_of_reading) + d.flux_offset * flux.accuracy;
}

// The reference temperature of a calibration trial: the mean of air and wall, moved by the draw
// within half their difference (the enclosure's true teq lies between them).
double reference_c(const CalibrationTrial& t, const Calibration& c, const Draw& d) {
    const auto air = c.instruments.at("air_temp_c"), wall = c.instruments.at("wall_temp_c");
    const double ta = t.air_temp_c + d.air * air.limit(t.air_temp_c);
    const double tw = t.wall_temp_c + d.wall * wall.limit(t.wall_temp_c);
    return 0.5 * (ta + tw) + d.reference * 0.5 * std::abs(t.wall_temp_c - t.air_temp_c);
}

struct Fit {
    double h = kNaN, residual_sd = kNaN, u_a = kNaN;
    int n = 0;
};

// Least squares through the origin of q = h x over the calibration trials (one zone).
Fit fit_zone(const Calibration& c, std::size_t z, const Draw& d) {
    const auto skin = c.instruments.at("skin_temp_c"), flux = c.instruments.at("heat_flux_w_m2");
    double sxx = 0.0, sxy = 0.0;
    std::vector<std::pair<double, double>> pts;
    for (const auto& t : c.trials) {
        if (z >= t.skin_temp_c.size() || !std::isfinite(t.skin_temp_c[z]) || !std::isfinite(t.q_w_m2[z])) continue;
        const double ts = t.skin_temp_c[z] + d.skin * skin.limit(t.skin_temp_c[z]);
        const double x = ts - reference_c(t, c, d);
        const double y = perturbed_q(t.q_w_m2[z], flux, d);
        sxx += x * x;
        sxy += x * y;
        pts.emplace_back(x, y);
    }
    Fit f;
    f.n = static_cast<int>(pts.size());
    if (f.n == 0 || !(sxx > 0.0)) return f;
    f.h = sxy / sxx;
    if (f.n >= 2) {
        double ss = 0.0;
        for (const auto& [x, y] : pts) ss += (y - f.h * x) * (y - f.h * x);
        f.residual_sd = std::sqrt(ss / (f.n - 1));
        f.u_a = f.residual_sd / std::sqrt(sxx);  // the slope's standard error, n - 1 dof
    }
    return f;
}

// A zone's exchange against its temperature difference x = t_sk - t_ref: q = a x + b x|x|, so
// h(x) = a + b|x|. ISO 14505-2's h_cal is constant (b = 0); free convection is not (h ~ x^0.25),
// and a teq far from the calibration's differences came out biased by more than its U95 (the
// cabin on the simulated lab: 0.3-0.7 K high). The curve is fitted to the calibration's own
// points (least squares in q over its trials, two or more distinct differences), read at the
// zone's own difference.
struct Curve {
    double a = kNaN, b = 0.0;
    double h(double x) const { return a + b * std::abs(x); }
    // The difference x at which this zone exchanges q: b x|x| + a x = q, solved stably.
    double difference(double q) const {
        const double disc = a * a + 4.0 * b * std::abs(q);
        if (b == 0.0 || !(disc >= 0.0)) return q / a;
        return 2.0 * q / (a + std::sqrt(disc));
    }
};

Curve fit_curve(const Calibration& c, std::size_t z, const Draw& d, bool curved) {
    Curve out;
    const Fit line = fit_zone(c, z, d);
    out.a = line.h;
    if (!curved || line.n < 2) return out;
    const auto skin = c.instruments.at("skin_temp_c"), flux = c.instruments.at("heat_flux_w_m2");
    // Normal equations of q = a x + b x|x| (no intercept).
    double s11 = 0.0, s12 = 0.0, s22 = 0.0, t1 = 0.0, t2 = 0.0, x_lo = 1e9, x_hi = -1e9;
    for (const auto& t : c.trials) {
        if (z >= t.skin_temp_c.size() || !std::isfinite(t.skin_temp_c[z]) || !std::isfinite(t.q_w_m2[z])) continue;
        const double x = t.skin_temp_c[z] + d.skin * skin.limit(t.skin_temp_c[z]) - reference_c(t, c, d);
        const double y = perturbed_q(t.q_w_m2[z], flux, d);
        const double u = x * std::abs(x);
        s11 += x * x;
        s12 += x * u;
        s22 += u * u;
        t1 += x * y;
        t2 += u * y;
        x_lo = std::min(x_lo, x);
        x_hi = std::max(x_hi, x);
    }
    const double det = s11 * s22 - s12 * s12;
    // Two distinct differences at least 2 K apart, or the curvature is the noise's.
    if (!(x_hi - x_lo >= 2.0) || !(det > 1e-9 * s11 * s22)) return out;
    const double a = (t1 * s22 - t2 * s12) / det, b = (s11 * t2 - s12 * t1) / det;
    if (!(a > 0.0)) return out;
    out.a = a;
    out.b = b;
    return out;
}

Draw draw_errors(const std::map<std::string, InstrumentSpec>& instruments, std::mt19937_64& rng) {
    const auto dist = [&](const char* ch) {
        const auto it = instruments.find(ch);
        return it == instruments.end() ? Distribution::rectangular : it->second.distribution;
    };
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    Draw d;
    d.skin = standardised_error_draw(dist("skin_temp_c"), rng);
    d.flux_offset = standardised_error_draw(dist("heat_flux_w_m2"), rng);
    d.flux_gain = standardised_error_draw(dist("heat_flux_w_m2"), rng);
    d.air = standardised_error_draw(dist("air_temp_c"), rng);
    d.wall = standardised_error_draw(dist("wall_temp_c"), rng);
    d.reference = unit(rng);
    return d;
}

// A Type A part: standard uncertainty and its degrees of freedom.
struct TypeA {
    double u = kNaN;
    double dof = 0.0;
};

// The replicates' mean: s / sqrt(n) on n - 1 dof (uncertainty.hpp; NaN for one replicate).
TypeA mean_type_a(const std::vector<double>& v) { return {type_a_of_mean(v), static_cast<double>(v.size()) - 1.0}; }

// Independent Type A parts added in quadrature, Welch-Satterthwaite dof (GUM G.4.1).
TypeA add(const std::vector<TypeA>& parts) {
    double var = 0.0, denom = 0.0;
    bool any = false;
    for (const auto& a : parts) {
        if (!std::isfinite(a.u)) continue;
        any = true;
        const double v = a.u * a.u;
        var += v;
        denom += a.dof > 0.0 ? v * v / a.dof : 0.0;
    }
    if (!any) return {};
    return {std::sqrt(var), denom > 0.0 ? var * var / denom : kInfinite};
}

Value make_value(double value, TypeA a, double u_b, double confidence) {
    Value v;
    v.value = value;
    v.u_a = a.u;
    v.u_b = u_b;
    const double ua = std::isfinite(a.u) ? a.u : 0.0;
    v.u_c = std::hypot(ua, u_b);
    v.dof = ua > 0.0 && a.dof > 0.0 ? std::min(kInfinite, std::pow(v.u_c, 4) / (std::pow(ua, 4) / a.dof)) : kInfinite;
    v.k = std::isfinite(a.u) ? coverage_factor(v.dof >= kInfinite ? kInfiniteDof : v.dof, confidence) : 2.0;
    v.U95 = v.k * v.u_c;
    return v;
}

// Running mean and variance (Welford) of a Monte Carlo output.
struct Spread {
    double n = 0.0, mean = 0.0, m2 = 0.0;
    void add(double x) {
        if (!std::isfinite(x)) return;
        n += 1.0;
        const double delta = x - mean;
        mean += delta / n;
        m2 += delta * (x - mean);
    }
    double sd() const { return n > 1.0 ? std::sqrt(m2 / (n - 1.0)) : 0.0; }
};

std::string fmt_c(double x) { return std::isfinite(x) ? fmt::format("{:.2f}", x) : std::string("-"); }

}  // namespace

// ---------------------------------------------------------------------------------------------
// Calibration

Calibration calibrate(const Campaign& campaign, const CampaignResult& analysis, const Limits& limits,
                      const Options& options) {
    Calibration c;
    c.campaign = campaign.name;
    c.limits = limits;
    for (const char* ch : {"skin_temp_c", "heat_flux_w_m2", "air_temp_c", "wall_temp_c"}) c.instruments[ch] = campaign.instrument(ch);
    const ZoneMap& map = campaign.zone_map;
    std::set<int> cases;
    for (const auto& cs : analysis.cases) {
        // teq is a dry heat exchange: a wet skin's evaporation would be fitted as convection.
        if (cs.wettedness && *cs.wettedness > 0.0)
            throw std::invalid_argument(fmt::format("{}: case {}: wettedness {:.2f}: a calibration for teq is run with a dry skin "
                                                    "(evaporation is not part of h_cal)",
                                                    campaign.name, cs.case_id, *cs.wettedness));
        for (const auto& t : cs.trials) {
            if (!t.included) {
                c.warnings.push_back(fmt::format("case {} trial {} left out: {}", cs.case_id, t.id, t.exclusion_reason));
                continue;
            }
            // The reference must be uniform: refuse, naming case, trial and quantity (docs/comfort.md).
            const auto where = fmt::format("{}: case {} trial {}", campaign.name, cs.case_id, t.id);
            if (!std::isfinite(t.wall_temp_c))
                throw std::invalid_argument(where + ": no wall temperature recorded, so the reference environment cannot be "
                                                    "shown uniform (air = wall)");
            if (!std::isfinite(t.air_speed_m_s))
                throw std::invalid_argument(where + ": no air speed recorded, so the reference environment cannot be shown "
                                                    "to be still air");
            const double gap = t.wall_temp_c - t.air_temp_c;
            if (std::abs(gap) > limits.max_wall_air_difference_k)
                throw std::invalid_argument(fmt::format(
                    "{}: wall - air = {:+.2f} K (wall {:.2f} °C, air {:.2f} °C) exceeds ±{:.2f} K: not a uniform reference "
                    "environment, no calibration written",
                    where, gap, t.wall_temp_c, t.air_temp_c, limits.max_wall_air_difference_k));
            if (t.air_speed_m_s > limits.max_air_speed_m_s)
                throw std::invalid_argument(fmt::format("{}: air speed {:.3f} m/s exceeds {:.2f} m/s: not still air, no "
                                                        "calibration written",
                                                        where, t.air_speed_m_s, limits.max_air_speed_m_s));
            CalibrationTrial ct;
            ct.id = t.id;
            ct.case_id = cs.case_id;
            ct.air_temp_c = t.air_temp_c;
            ct.wall_temp_c = t.wall_temp_c;
            ct.air_speed_m_s = t.air_speed_m_s;
            ct.skin_temp_c = t.zone_skin_temp_c;
            ct.q_w_m2 = t.zone_q_w_m2;
            c.trials.push_back(std::move(ct));
            cases.insert(cs.case_id);
        }
    }
    for (const auto& cs : analysis.unanalysed_cases)
        c.warnings.push_back(fmt::format("case {}: no steady trial, left out", cs.case_id));
    if (c.trials.empty())
        throw std::invalid_argument(fmt::format("{}: no steady calibration trial (docs/comfort.md)", campaign.name));
    if (cases.size() < 2)
        c.warnings.push_back("one case only: the fit is through the origin from one temperature difference; several cases "
                             "(different air = wall temperatures) show whether q is proportional to it");
    // Measured fit, then the Monte Carlo over the instruments (Type B of each h).
    std::vector<Fit> fits;
    for (std::size_t z = 0; z < map.size(); ++z) {
        fits.push_back(fit_zone(c, z, Draw{}));
        double max_dx = 0.0;
        for (const auto& t : c.trials)
            if (z < t.skin_temp_c.size() && std::isfinite(t.skin_temp_c[z]))
                max_dx = std::max(max_dx, std::abs(t.skin_temp_c[z] - 0.5 * (t.air_temp_c + t.wall_temp_c)));
        if (!std::isfinite(fits.back().h) || max_dx < 1.0)
            throw std::invalid_argument(fmt::format("{}: zone {} ({}): skin and reference temperature within {:.2f} K in every "
                                                    "trial: nothing to fit h from (run cases with the air well below the skin)",
                                                    campaign.name, z + 1, map.zones[z].name, max_dx));
    }
    std::mt19937_64 rng(options.seed);
    const int draws = std::max(100, options.monte_carlo_draws);
    c.draws = draws;
    std::vector<Spread> spread(map.size());
    Spread whole;
    const double area = map.total_area_m2();
    for (int i = 0; i < draws; ++i) {
        const Draw d = draw_errors(c.instruments, rng);
        double hw = 0.0;
        for (std::size_t z = 0; z < map.size(); ++z) {
            const double h = fit_zone(c, z, d).h;
            spread[z].add(h);
            hw += map.zones[z].area_m2 / area * h;
        }
        whole.add(hw);
    }
    double hw = 0.0;
    std::vector<TypeA> whole_a;
    for (std::size_t z = 0; z < map.size(); ++z) {
        ZoneCoefficient zc;
        zc.zone = map.zones[z].zone;
        zc.name = map.zones[z].name;
        zc.region = map.zones[z].region;
        zc.area_m2 = map.zones[z].area_m2;
        zc.points = fits[z].n;
        zc.residual_sd_w_m2 = fits[z].residual_sd;
        const TypeA a{fits[z].u_a, static_cast<double>(fits[z].n - 1)};
        zc.h = make_value(fits[z].h, a, spread[z].sd(), options.confidence);
        hw += map.zones[z].area_m2 / area * fits[z].h;
        whole_a.push_back({map.zones[z].area_m2 / area * a.u, a.dof});
        c.zones.push_back(std::move(zc));
    }
    c.h_whole_body = make_value(hw, add(whole_a), whole.sd(), options.confidence);
    return c;
}

namespace {

nlohmann::json value_json(const Value& v) {
    auto num = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(); };
    return {{"value", v.value}, {"u_a", num(v.u_a)}, {"u_b", v.u_b}, {"u_c", v.u_c},
            {"dof", v.dof >= kInfinite ? nlohmann::json() : nlohmann::json(v.dof)}, {"k", v.k}, {"U95", v.U95}};
}

nlohmann::json spec_json(const InstrumentSpec& s) {
    return {{"accuracy", s.accuracy}, {"accuracy_of_reading", s.accuracy_of_reading}, {"distribution", to_string(s.distribution)}};
}

nlohmann::json numbers(const std::vector<double>& v) {
    nlohmann::json a = nlohmann::json::array();
    for (double x : v) a.push_back(std::isfinite(x) ? nlohmann::json(x) : nlohmann::json());
    return a;
}

}  // namespace

nlohmann::json to_json(const Calibration& c) {
    nlohmann::json j;
    j["format"] = c.format;
    j["campaign"] = c.campaign;
    j["program"] = c.program;
    j["created_utc"] = c.created_utc;
    j["heat_flux_sign"] = kHeatFluxSign;
    j["method"] = {{"model", "q = h_cal (t_skin - t_eq,ref), least squares through the origin over the trials (ISO 14505-2)"},
                   {"reference", "t_eq,ref = (t_air + t_wall) / 2; the true value lies between them (a Type B term)"},
                   {"type_a", "the slope's standard error from the residuals, n - 1 dof"},
                   {"type_b", fmt::format("Monte Carlo over the instruments' specs, {} draws (GUM Supplement 1)", c.draws)}};
    j["limits"] = {{"max_wall_air_difference_k", c.limits.max_wall_air_difference_k},
                   {"max_air_speed_m_s", c.limits.max_air_speed_m_s}};
    j["instruments"] = nlohmann::json::object();
    for (const auto& [ch, s] : c.instruments) j["instruments"][ch] = spec_json(s);
    j["h_whole_body_w_m2k"] = value_json(c.h_whole_body);
    j["zones"] = nlohmann::json::array();
    for (const auto& z : c.zones)
        j["zones"].push_back({{"zone", z.zone}, {"name", z.name}, {"region", z.region}, {"area_m2", z.area_m2},
                              {"h_w_m2k", value_json(z.h)}, {"residual_sd_w_m2", std::isfinite(z.residual_sd_w_m2) ? nlohmann::json(z.residual_sd_w_m2) : nlohmann::json()},
                              {"points", z.points}});
    j["trials"] = nlohmann::json::array();
    for (const auto& t : c.trials)
        j["trials"].push_back({{"id", t.id}, {"case", t.case_id}, {"air_temp_c", t.air_temp_c}, {"wall_temp_c", t.wall_temp_c},
                               {"air_speed_m_s", t.air_speed_m_s}, {"skin_temp_c", numbers(t.skin_temp_c)}, {"q_w_m2", numbers(t.q_w_m2)}});
    j["warnings"] = c.warnings;
    return j;
}

std::string to_text(const Calibration& c) {
    std::ostringstream o;
    o << fmt::format("teq calibration from {}: {} trials, reference (air + wall)/2, values ± U95\n", c.campaign, c.trials.size());
    o << fmt::format("whole body (area-weighted)  h = {:.3f} ± {:.3f} W/m²K\n\n", c.h_whole_body.value, c.h_whole_body.U95);
    o << fmt::format("{:>4}  {:<18} {:>8} {:>8} {:>8} {:>8} {:>10}\n", "zone", "name", "h", "U95", "u_A", "u_B", "resid W/m²");
    for (const auto& z : c.zones)
        o << fmt::format("{:>4}  {:<18} {:>8.3f} {:>8.3f} {:>8.3f} {:>8.3f} {:>10.2f}\n", z.zone, z.name, z.h.value, z.h.U95,
                         std::isfinite(z.h.u_a) ? z.h.u_a : 0.0, z.h.u_b, std::isfinite(z.residual_sd_w_m2) ? z.residual_sd_w_m2 : 0.0);
    for (const auto& w : c.warnings) o << "warning: " << w << "\n";
    return o.str();
}

namespace {

// Field access that names the file and the JSON pointer of what is wrong.
struct Reader {
    std::string file;
    [[noreturn]] void fail(const std::string& field, const std::string& what) const { throw InputError(file, 0, 0, field, what); }
    const nlohmann::json& at(const nlohmann::json& j, const std::string& key, const std::string& path) const {
        if (!j.is_object() || !j.contains(key)) fail(path + "/" + key, "missing");
        return j.at(key);
    }
    double number(const nlohmann::json& j, const std::string& key, const std::string& path, bool nullable = false) const {
        const auto& v = at(j, key, path);
        if (nullable && v.is_null()) return kNaN;
        if (!v.is_number()) fail(path + "/" + key, "not a number");
        const double x = v.get<double>();
        if (!std::isfinite(x)) fail(path + "/" + key, "not finite");
        return x;
    }
    std::string string(const nlohmann::json& j, const std::string& key, const std::string& path) const {
        const auto& v = at(j, key, path);
        if (!v.is_string()) fail(path + "/" + key, "not a string");
        return v.get<std::string>();
    }
    std::vector<double> numbers(const nlohmann::json& j, const std::string& key, const std::string& path) const {
        const auto& v = at(j, key, path);
        if (!v.is_array()) fail(path + "/" + key, "not an array");
        std::vector<double> out;
        for (std::size_t i = 0; i < v.size(); ++i) {
            if (v[i].is_null()) out.push_back(kNaN);
            else if (v[i].is_number()) out.push_back(v[i].get<double>());
            else fail(fmt::format("{}/{}/{}", path, key, i), "not a number");
        }
        return out;
    }
    Value value(const nlohmann::json& j, const std::string& key, const std::string& path) const {
        const auto& v = at(j, key, path);
        const std::string p = path + "/" + key;
        Value out;
        out.value = number(v, "value", p);
        out.u_a = number(v, "u_a", p, true);
        out.u_b = number(v, "u_b", p);
        out.u_c = number(v, "u_c", p);
        const double dof = number(v, "dof", p, true);
        out.dof = std::isfinite(dof) ? dof : kInfinite;
        out.k = number(v, "k", p);
        out.U95 = number(v, "U95", p);
        if (out.u_b < 0.0 || out.U95 < 0.0) fail(p, "negative uncertainty");
        return out;
    }
};

}  // namespace

Calibration calibration_from_json(const nlohmann::json& j, const std::string& file) {
    const Reader r{file};
    if (!j.is_object()) r.fail("", "not a JSON object");
    Calibration c;
    c.format = r.string(j, "format", "");
    if (c.format != kCalibrationFormat)
        r.fail("/format", fmt::format("'{}' is not {} (a newer file needs a newer manikin)", c.format, kCalibrationFormat));
    c.campaign = r.string(j, "campaign", "");
    if (j.contains("program") && j["program"].is_string()) c.program = j["program"].get<std::string>();
    if (j.contains("created_utc") && j["created_utc"].is_string()) c.created_utc = j["created_utc"].get<std::string>();
    const auto& lim = r.at(j, "limits", "");
    c.limits.max_wall_air_difference_k = r.number(lim, "max_wall_air_difference_k", "/limits");
    c.limits.max_air_speed_m_s = r.number(lim, "max_air_speed_m_s", "/limits");
    const auto& inst = r.at(j, "instruments", "");
    for (const char* ch : {"skin_temp_c", "heat_flux_w_m2", "air_temp_c", "wall_temp_c"}) {
        const std::string p = std::string("/instruments/") + ch;
        const auto& s = r.at(inst, ch, "/instruments");
        InstrumentSpec spec;
        spec.accuracy = r.number(s, "accuracy", p);
        spec.accuracy_of_reading = r.number(s, "accuracy_of_reading", p);
        const auto d = distribution_from_string(r.string(s, "distribution", p));
        if (!d) r.fail(p + "/distribution", "unknown distribution");
        spec.distribution = *d;
        if (spec.accuracy < 0.0 || spec.accuracy_of_reading < 0.0) r.fail(p, "negative accuracy");
        c.instruments[ch] = spec;
    }
    c.h_whole_body = r.value(j, "h_whole_body_w_m2k", "");
    const auto& zones = r.at(j, "zones", "");
    if (!zones.is_array() || zones.empty()) r.fail("/zones", "not a non-empty array");
    for (std::size_t i = 0; i < zones.size(); ++i) {
        const std::string p = fmt::format("/zones/{}", i);
        ZoneCoefficient z;
        z.zone = static_cast<int>(r.number(zones[i], "zone", p));
        if (z.zone != static_cast<int>(i) + 1) r.fail(p + "/zone", fmt::format("zones must be numbered 1..N in order; expected {}", i + 1));
        z.name = r.string(zones[i], "name", p);
        z.region = r.string(zones[i], "region", p);
        z.area_m2 = r.number(zones[i], "area_m2", p);
        z.h = r.value(zones[i], "h_w_m2k", p);
        if (!(z.h.value > 0.0)) r.fail(p + "/h_w_m2k/value", "h must be positive");
        z.residual_sd_w_m2 = r.number(zones[i], "residual_sd_w_m2", p, true);
        z.points = static_cast<int>(r.number(zones[i], "points", p));
        c.zones.push_back(std::move(z));
    }
    const auto& trials = r.at(j, "trials", "");
    if (!trials.is_array() || trials.empty()) r.fail("/trials", "not a non-empty array");
    for (std::size_t i = 0; i < trials.size(); ++i) {
        const std::string p = fmt::format("/trials/{}", i);
        CalibrationTrial t;
        t.id = r.string(trials[i], "id", p);
        t.case_id = static_cast<int>(r.number(trials[i], "case", p));
        t.air_temp_c = r.number(trials[i], "air_temp_c", p);
        t.wall_temp_c = r.number(trials[i], "wall_temp_c", p);
        t.air_speed_m_s = r.number(trials[i], "air_speed_m_s", p);
        t.skin_temp_c = r.numbers(trials[i], "skin_temp_c", p);
        t.q_w_m2 = r.numbers(trials[i], "q_w_m2", p);
        if (t.skin_temp_c.size() != c.zones.size()) r.fail(p + "/skin_temp_c", fmt::format("{} values for {} zones", t.skin_temp_c.size(), c.zones.size()));
        if (t.q_w_m2.size() != c.zones.size()) r.fail(p + "/q_w_m2", fmt::format("{} values for {} zones", t.q_w_m2.size(), c.zones.size()));
        c.trials.push_back(std::move(t));
    }
    if (j.contains("warnings") && j["warnings"].is_array())
        for (const auto& w : j["warnings"])
            if (w.is_string()) c.warnings.push_back(w.get<std::string>());
    return c;
}

Calibration read_calibration(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) throw InputError(file.string(), 0, 0, "", "cannot open the calibration file");
    std::ostringstream text;
    text << in.rdbuf();
    const std::string s = text.str();
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(s);
    } catch (const nlohmann::json::parse_error& e) {
        // Name the line and column of the byte the parser stopped at.
        const std::size_t at = std::min(e.byte > 0 ? e.byte - 1 : 0, s.size());
        const std::size_t line = 1 + static_cast<std::size_t>(std::count(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(at), '\n'));
        const std::size_t nl = s.rfind('\n', at > 0 ? at - 1 : 0);
        const std::size_t column = at - (nl == std::string::npos || at == 0 ? 0 : nl + 1) + 1;
        throw InputError(file.string(), line, column, "", "not JSON: " + std::string(e.what()));
    }
    return calibration_from_json(j, file.string());
}

// ---------------------------------------------------------------------------------------------
// Neutral ranges

NeutralRanges placeholder_ranges(const ZoneMap& map) {
    NeutralRanges r;
    r.placeholder = true;
    r.source = "placeholder 21-26 °C for every part, not from a source: give the lab's ranges with --ranges";
    for (const auto& z : map.zones) {
        r.parts[z.name] = {21.0, 26.0};
        r.parts[z.region] = {21.0, 26.0};
    }
    r.parts["whole_body"] = {21.0, 26.0};
    return r;
}

NeutralRanges read_ranges(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) throw InputError(file.string(), 0, 0, "", "cannot open the neutral-ranges file");
    NeutralRanges r;
    r.source = file.filename().string();
    std::string line;
    std::size_t n = 0;
    auto parse = [&](const std::string& cell, const char* field) {
        double x = 0.0;
        std::size_t used = 0;
        try {
            x = std::stod(cell, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        while (used < cell.size() && (cell[used] == ' ' || cell[used] == '\r')) ++used;
        if (cell.empty() || used != cell.size() || !std::isfinite(x))
            throw InputError(file.string(), n, 0, field, fmt::format("'{}' is not a number (°C)", cell));
        return x;
    };
    while (std::getline(in, line)) {
        ++n;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (n == 1) {
            if (line != "part,cold_limit_c,warm_limit_c")
                throw InputError(file.string(), 1, 0, "header", "expected 'part,cold_limit_c,warm_limit_c'");
            continue;
        }
        if (line.empty() || line[0] == '#') continue;
        std::vector<std::string> cells;
        std::stringstream ss(line);
        for (std::string cell; std::getline(ss, cell, ',');) cells.push_back(cell);
        if (cells.size() != 3) throw InputError(file.string(), n, 0, "", fmt::format("{} fields, expected 3", cells.size()));
        if (cells[0].empty()) throw InputError(file.string(), n, 1, "part", "empty");
        const Range range{parse(cells[1], "cold_limit_c"), parse(cells[2], "warm_limit_c")};
        if (!(range.cold_limit_c < range.warm_limit_c))
            throw InputError(file.string(), n, 0, "warm_limit_c", "must be above cold_limit_c");
        if (!r.parts.emplace(cells[0], range).second) throw InputError(file.string(), n, 1, "part", "'" + cells[0] + "' given twice");
    }
    if (r.parts.empty()) throw InputError(file.string(), n, 0, "", "no ranges");
    return r;
}

// ---------------------------------------------------------------------------------------------
// teq of a campaign

namespace {

struct ReplicateData {
    std::vector<double> skin_c, q_w_m2;
};

// teq of every zone, region and the whole body for one replicate under one draw.
struct PartValues {
    std::vector<double> zone, region;
    double whole = kNaN;
};

PartValues part_values(const ReplicateData& rep, const std::vector<Curve>& h, const ZoneMap& map,
                       const std::vector<std::string>& regions, const InstrumentSpec& skin, const InstrumentSpec& flux,
                       const Draw& d) {
    PartValues v;
    v.zone.assign(map.size(), kNaN);
    std::map<std::string, std::pair<double, double>> reg;  // sum A h teq, sum A h
    double wn = 0.0, wd = 0.0;
    for (std::size_t z = 0; z < map.size(); ++z) {
        if (z >= rep.skin_c.size() || !std::isfinite(rep.skin_c[z]) || !std::isfinite(rep.q_w_m2[z])) continue;
        const double ts = rep.skin_c[z] + d.skin * skin.limit(rep.skin_c[z]);
        const double q = perturbed_q(rep.q_w_m2[z], flux, d);
        const double x = h[z].difference(q);
        const double teq = ts - x;  // ISO 14505-2's definition per zone: t_sk - q / h_cal
        v.zone[z] = teq;
        const double w = map.zones[z].area_m2 * h[z].h(x);
        reg[map.zones[z].region].first += w * teq;
        reg[map.zones[z].region].second += w;
        wn += w * teq;
        wd += w;
    }
    for (const auto& name : regions) {
        const auto it = reg.find(name);
        v.region.push_back(it == reg.end() || !(it->second.second > 0.0) ? kNaN : it->second.first / it->second.second);
    }
    v.whole = wd > 0.0 ? wn / wd : kNaN;
    return v;
}

std::string verdict(const Value& v, const std::optional<Range>& r) {
    if (!r) return "";
    if (v.value + v.U95 < r->cold_limit_c) return "cold";
    if (v.value - v.U95 > r->warm_limit_c) return "warm";
    if (v.value - v.U95 >= r->cold_limit_c && v.value + v.U95 <= r->warm_limit_c) return "neutral";
    return v.value < r->cold_limit_c ? "cold?" : v.value > r->warm_limit_c ? "warm?" : "neutral?";
}

}  // namespace

Result compute(const Campaign& campaign, const CampaignResult& analysis, const Calibration& calibration,
               const NeutralRanges& ranges, const Options& options) {
    Result out;
    out.campaign = campaign.name;
    out.calibration_campaign = calibration.campaign;
    out.options = options;
    out.ranges = ranges;
    const ZoneMap& map = campaign.zone_map;
    if (calibration.zones.size() != map.size())
        throw std::invalid_argument(fmt::format("the calibration ({}) has {} zones, the campaign {} has {}: not the same manikin",
                                                calibration.campaign, calibration.zones.size(), campaign.name, map.size()));
    for (std::size_t z = 0; z < map.size(); ++z)
        if (calibration.zones[z].name != map.zones[z].name)
            throw std::invalid_argument(fmt::format("zone {}: the calibration names it '{}', the campaign {} '{}': not the same zone map",
                                                    z + 1, calibration.zones[z].name, campaign.name, map.zones[z].name));
    const InstrumentSpec skin = campaign.instrument("skin_temp_c"), flux = campaign.instrument("heat_flux_w_m2");
    for (const char* ch : {"skin_temp_c", "heat_flux_w_m2"}) {
        const auto a = calibration.instruments.at(ch), b = campaign.instrument(ch);
        if (a.accuracy != b.accuracy || a.accuracy_of_reading != b.accuracy_of_reading || a.distribution != b.distribution)
            out.warnings.push_back(fmt::format("{}: the campaign's spec differs from the calibration's: the Type B assumes the "
                                               "same manikin (its errors drawn once for both)", ch));
    }
    std::vector<std::string> regions;
    for (const auto& z : map.zones)
        if (std::find(regions.begin(), regions.end(), z.region) == regions.end()) regions.push_back(z.region);
    std::vector<Curve> h_cal;
    for (std::size_t z = 0; z < calibration.zones.size(); ++z) {
        h_cal.push_back(fit_curve(calibration, z, Draw{}, options.curved_h));
        if (!options.curved_h || !std::isfinite(h_cal.back().a)) h_cal.back() = Curve{calibration.zones[z].h.value, 0.0};
    }

    for (const auto& cs : analysis.unanalysed_cases) out.warnings.push_back(fmt::format("case {}: no steady trial, left out", cs.case_id));
    for (const auto& cs : analysis.cases) {
        std::vector<ReplicateData> reps;
        std::vector<double> ta, tw, va;
        for (const auto& t : cs.trials) {
            if (!t.included) {
                out.warnings.push_back(fmt::format("case {} trial {} left out: {}", cs.case_id, t.id, t.exclusion_reason));
                continue;
            }
            reps.push_back({t.zone_skin_temp_c, t.zone_q_w_m2});
            ta.push_back(t.air_temp_c);
            tw.push_back(t.wall_temp_c);
            va.push_back(t.air_speed_m_s);
        }
        if (reps.empty()) continue;
        CaseTeq c;
        c.case_id = cs.case_id;
        c.replicates = static_cast<int>(reps.size());
        c.air_temp_c = mean(ta);
        c.wall_temp_c = mean(tw);
        c.air_speed_m_s = mean(va);
        // Measured values: per replicate, then their mean and Type A.
        std::vector<PartValues> measured;
        for (const auto& rep : reps) measured.push_back(part_values(rep, h_cal, map, regions, skin, flux, Draw{}));
        const auto mean_of = [&](auto get) {
            std::vector<double> v;
            for (const auto& m : measured) v.push_back(get(m));
            return v;
        };
        // The calibration's own Type A: each zone's h moved by its u_A, the change of the part's
        // value (the zones' fits are independent: added in quadrature, Welch-Satterthwaite).
        std::vector<PartValues> shifted;  // per zone
        for (std::size_t z = 0; z < map.size(); ++z) {
            std::vector<Curve> h = h_cal;
            if (std::isfinite(calibration.zones[z].h.u_a)) h[z].a += calibration.zones[z].h.u_a;
            PartValues sum;
            sum.zone.assign(map.size(), 0.0);
            sum.region.assign(regions.size(), 0.0);
            sum.whole = 0.0;
            for (const auto& rep : reps) {
                const PartValues p = part_values(rep, h, map, regions, skin, flux, Draw{});
                for (std::size_t i = 0; i < map.size(); ++i) sum.zone[i] += p.zone[i] / static_cast<double>(reps.size());
                for (std::size_t i = 0; i < regions.size(); ++i) sum.region[i] += p.region[i] / static_cast<double>(reps.size());
                sum.whole += p.whole / static_cast<double>(reps.size());
            }
            shifted.push_back(std::move(sum));
        }
        // Monte Carlo over the instruments: h refitted from the calibration's data under the same
        // draw of the manikin's errors that perturbs this campaign's data.
        std::mt19937_64 rng(options.seed + static_cast<unsigned>(cs.case_id));
        const int draws = std::max(100, options.monte_carlo_draws);
        std::vector<Spread> zone_spread(map.size()), region_spread(regions.size());
        Spread whole_spread;
        std::vector<Curve> h(map.size());
        for (int i = 0; i < draws; ++i) {
            const Draw d = draw_errors(calibration.instruments, rng);
            for (std::size_t z = 0; z < map.size(); ++z) h[z] = fit_curve(calibration, z, d, options.curved_h);
            PartValues sum;
            sum.zone.assign(map.size(), 0.0);
            sum.region.assign(regions.size(), 0.0);
            sum.whole = 0.0;
            for (const auto& rep : reps) {
                const PartValues p = part_values(rep, h, map, regions, skin, flux, d);
                for (std::size_t k = 0; k < map.size(); ++k) sum.zone[k] += p.zone[k] / static_cast<double>(reps.size());
                for (std::size_t k = 0; k < regions.size(); ++k) sum.region[k] += p.region[k] / static_cast<double>(reps.size());
                sum.whole += p.whole / static_cast<double>(reps.size());
            }
            for (std::size_t k = 0; k < map.size(); ++k) zone_spread[k].add(sum.zone[k]);
            for (std::size_t k = 0; k < regions.size(); ++k) region_spread[k].add(sum.region[k]);
            whole_spread.add(sum.whole);
        }
        const auto finish = [&](const std::string& name, const std::vector<double>& values, double base,
                                const std::vector<double>& moved, double u_b, double area, double ts, double q) {
            PartTeq p;
            p.name = name;
            p.area_m2 = area;
            p.skin_temp_c = ts;
            p.q_w_m2 = q;
            std::vector<TypeA> parts{mean_type_a(values)};
            for (std::size_t z = 0; z < map.size(); ++z) {
                const auto& cz = calibration.zones[z].h;
                if (std::isfinite(cz.u_a) && std::isfinite(moved[z])) parts.push_back({std::abs(moved[z] - base), cz.dof});
            }
            p.teq = make_value(base, add(parts), u_b, options.confidence);
            if (const auto it = ranges.parts.find(name); it != ranges.parts.end()) p.neutral = it->second;
            p.verdict = verdict(p.teq, p.neutral);
            return p;
        };
        // Area-weighted skin temperature and flux of a set of zones (over the replicates).
        const auto skin_q = [&](auto in) {
            double a = 0.0, ts = 0.0, q = 0.0;
            for (std::size_t z = 0; z < map.size(); ++z) {
                if (!in(z)) continue;
                double s = 0.0, f = 0.0;
                for (const auto& rep : reps) {
                    s += rep.skin_c[z] / static_cast<double>(reps.size());
                    f += rep.q_w_m2[z] / static_cast<double>(reps.size());
                }
                a += map.zones[z].area_m2;
                ts += map.zones[z].area_m2 * s;
                q += map.zones[z].area_m2 * f;
            }
            return std::tuple<double, double, double>{a, ts / a, q / a};
        };
        for (std::size_t z = 0; z < map.size(); ++z) {
            const auto values = mean_of([&](const PartValues& m) { return m.zone[z]; });
            std::vector<double> moved;
            for (const auto& s : shifted) moved.push_back(s.zone[z]);
            const auto [a, ts, q] = skin_q([&](std::size_t k) { return k == z; });
            c.zones.push_back(finish(map.zones[z].name, values, mean(values), moved, zone_spread[z].sd(), a, ts, q));
        }
        for (std::size_t k = 0; k < regions.size(); ++k) {
            const auto values = mean_of([&](const PartValues& m) { return m.region[k]; });
            std::vector<double> moved;
            for (const auto& s : shifted) moved.push_back(s.region[k]);
            const auto [a, ts, q] = skin_q([&](std::size_t z) { return map.zones[z].region == regions[k]; });
            c.regions.push_back(finish(regions[k], values, mean(values), moved, region_spread[k].sd(), a, ts, q));
        }
        {
            const auto values = mean_of([&](const PartValues& m) { return m.whole; });
            std::vector<double> moved;
            for (const auto& s : shifted) moved.push_back(s.whole);
            const auto [a, ts, q] = skin_q([](std::size_t) { return true; });
            c.whole_body = finish("whole_body", values, mean(values), moved, whole_spread.sd(), a, ts, q);
        }
        if (c.replicates == 1) c.notes.push_back("one replicate: Type A from the calibration's fit only");
        // h_cal is a straight line through the calibration's points; free convection is not
        // straight (h ~ dT^0.25), so a teq beyond the references the calibration saw rests on an
        // extrapolation its U95 does not carry (ISO 14505-2 calibrates over the range measured).
        if (!calibration.trials.empty()) {
            double ref_lo = 1e9, ref_hi = -1e9;
            for (const auto& t : calibration.trials) {
                const double ref = 0.5 * (t.air_temp_c + t.wall_temp_c);
                ref_lo = std::min(ref_lo, ref);
                ref_hi = std::max(ref_hi, ref);
            }
            std::string beyond;
            int count = 0;
            for (const auto& z : c.zones)
                if (z.teq.value < ref_lo - 1.0 || z.teq.value > ref_hi + 1.0) {
                    beyond += fmt::format("{}{} {:.1f}", count ? ", " : "", z.name, z.teq.value);
                    ++count;
                }
            if (count)
                c.notes.push_back(fmt::format("{} zone{} beyond the calibration's references ({:.1f}-{:.1f} °C) by more than 1 K: "
                                              "{}; h_cal is extrapolated there, by a straight line where free convection "
                                              "is not, and U95 does not carry that (calibrate over the range measured)",
                                              count, count == 1 ? "" : "s", ref_lo, ref_hi, beyond));
        }
        if (cs.wettedness && *cs.wettedness > 0.0)
            out.warnings.push_back(fmt::format("case {}: wettedness {:.2f}: q includes evaporation, so teq (a dry-heat index) "
                                               "comes out too high; measure teq with a dry skin",
                                               cs.case_id, *cs.wettedness));
        out.cases.push_back(std::move(c));
    }
    if (out.cases.empty()) throw std::invalid_argument(fmt::format("{}: no case with a steady trial", campaign.name));
    return out;
}

namespace {

nlohmann::json part_json(const PartTeq& p) {
    nlohmann::json j = value_json(p.teq);
    j["name"] = p.name;
    j["area_m2"] = p.area_m2;
    j["teq_c"] = p.teq.value;
    j["skin_temp_c"] = p.skin_temp_c;
    j["q_w_m2"] = p.q_w_m2;
    j["neutral"] = p.neutral ? nlohmann::json{{"cold_limit_c", p.neutral->cold_limit_c}, {"warm_limit_c", p.neutral->warm_limit_c}}
                             : nlohmann::json();
    j["verdict"] = p.verdict.empty() ? nlohmann::json() : nlohmann::json(p.verdict);
    return j;
}

}  // namespace

nlohmann::json to_json(const Result& r) {
    nlohmann::json j;
    j["campaign"] = r.campaign;
    j["calibration_campaign"] = r.calibration_campaign;
    j["heat_flux_sign"] = kHeatFluxSign;
    j["method"] = {{"zone", "teq = t_skin - q / h_cal (ISO 14505-2)"},
                   {"h_cal", r.options.curved_h ? "the calibration's curve h(x) = a + b|x|, read at the zone's own difference x = t_skin - teq"
                                                : "constant (ISO 14505-2)"},
                   {"region_whole_body", "the uniform temperature in which the part loses its zones' heat: teq weighted by A_z h_cal,z"},
                   {"type_a", "replicates s/sqrt(n) and the calibration fit's standard errors, Welch-Satterthwaite"},
                   {"type_b", fmt::format("Monte Carlo over the instruments, {} draws; the manikin's errors shared with the calibration",
                                          r.options.monte_carlo_draws)},
                   {"confidence", r.options.confidence}};
    j["neutral_ranges"] = {{"source", r.ranges.source}, {"placeholder", r.ranges.placeholder}};
    j["cases"] = nlohmann::json::array();
    for (const auto& c : r.cases) {
        auto num = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(); };
        nlohmann::json x = {{"case", c.case_id}, {"replicates", c.replicates}, {"air_temp_c", num(c.air_temp_c)},
                            {"wall_temp_c", num(c.wall_temp_c)}, {"air_speed_m_s", num(c.air_speed_m_s)},
                            {"whole_body", part_json(c.whole_body)}, {"notes", c.notes}};
        x["regions"] = nlohmann::json::array();
        for (const auto& p : c.regions) x["regions"].push_back(part_json(p));
        x["zones"] = nlohmann::json::array();
        for (std::size_t i = 0; i < c.zones.size(); ++i) {
            auto z = part_json(c.zones[i]);
            z["zone"] = i + 1;
            x["zones"].push_back(std::move(z));
        }
        j["cases"].push_back(std::move(x));
    }
    j["warnings"] = r.warnings;
    return j;
}

std::string to_text(const Result& r) {
    std::ostringstream o;
    o << fmt::format("Equivalent temperature (ISO 14505-2): {} with the calibration from {}\n", r.campaign, r.calibration_campaign);
    o << fmt::format("teq ± U95 (°C; Type A replicates + calibration fit, Type B instruments); h_cal {}; neutral ranges: {}\n",
                     r.options.curved_h ? "read from the calibration's curve at each zone's difference" : "constant (ISO 14505-2)",
                     r.ranges.source);
    const auto row = [&](const PartTeq& p) {
        return fmt::format("  {:<18} {:>7} ± {:<5.2f} {:>7} {:>9}  {}\n", p.name, fmt_c(p.teq.value), p.teq.U95, fmt_c(p.skin_temp_c),
                           fmt::format("{:.1f}", p.q_w_m2),
                           p.neutral ? fmt::format("{:<9} [{:.1f}, {:.1f}]", p.verdict, p.neutral->cold_limit_c, p.neutral->warm_limit_c) : "");
    };
    for (const auto& c : r.cases) {
        o << fmt::format("\ncase {}: {} replicate{}, air {} °C, wall {} °C, air speed {} m/s\n", c.case_id, c.replicates,
                         c.replicates == 1 ? "" : "s", fmt_c(c.air_temp_c), fmt_c(c.wall_temp_c),
                         std::isfinite(c.air_speed_m_s) ? fmt::format("{:.2f}", c.air_speed_m_s) : "-");
        o << fmt::format("  {:<18} {:>7}   {:<5} {:>7} {:>9}  {}\n", "part", "teq", "U95", "skin", "q W/m²", "neutral range");
        o << row(c.whole_body);
        for (const auto& p : c.regions) o << row(p);
        o << "  zones:\n";
        for (const auto& p : c.zones) o << row(p);
        for (const auto& n : c.notes) o << "  note: " << n << "\n";
    }
    for (const auto& w : r.warnings) o << "warning: " << w << "\n";
    return o.str();
}

plot::Figure comfort_figure(const Result& r) {
    plot::Figure f;
    const double panel_h = 420.0;
    f.width_px = 900.0;
    f.height_px = 84.0 + panel_h * static_cast<double>(r.cases.size());
    f.title = fmt::format("Equivalent temperature per zone: {} (calibration {})", r.campaign, r.calibration_campaign);
    f.notes.push_back("teq ± U95 (ISO 14505-2) beside each zone's neutral range (grey)");
    f.notes.push_back(r.ranges.placeholder ? std::string("neutral ranges: placeholders 21-26 °C, not from a source (--ranges)")
                                           : "neutral ranges: " + r.ranges.source);
    double y = 74.0;
    for (const auto& c : r.cases) {
        plot::XYPanel p;
        p.box = {0.0, y, f.width_px, panel_h};
        y += panel_h;
        p.title = fmt::format("case {}: whole body {:.1f} ± {:.1f} °C", c.case_id, c.whole_body.teq.value, c.whole_body.teq.U95);
        p.x.label = "Zone";
        p.y.label = "Equivalent temperature teq (°C)";
        plot::Series range, inside, outside;
        range.label = "neutral range";
        range.colour = "#9e9e9e";
        range.markers = false;
        range.line_width_px = 6.0;
        range.opacity = 0.6;
        inside.label = "teq ± U95, within the range";
        inside.colour = "#2ca02c";
        outside.label = "teq ± U95, outside or straddling";
        outside.colour = "#d62728";
        for (std::size_t z = 0; z < c.zones.size(); ++z) {
            const auto& zt = c.zones[z];
            p.x.categories.push_back(zt.name);
            if (zt.neutral) {
                range.x.push_back(static_cast<double>(z) - 0.2);  // beside the teq bar, not under it
                range.y.push_back(0.5 * (zt.neutral->cold_limit_c + zt.neutral->warm_limit_c));
                range.y_err.push_back(0.5 * (zt.neutral->warm_limit_c - zt.neutral->cold_limit_c));
            }
            auto& s = zt.verdict == "neutral" ? inside : outside;
            s.x.push_back(static_cast<double>(z));
            s.y.push_back(zt.teq.value);
            s.y_err.push_back(zt.teq.U95);
            s.tooltips.push_back(fmt::format("{}: {:.2f} ± {:.2f} °C{}", zt.name, zt.teq.value, zt.teq.U95,
                                             zt.verdict.empty() ? "" : " (" + zt.verdict + ")"));
        }
        for (auto* s : {&range, &inside, &outside})
            if (!s->x.empty()) p.series.push_back(*s);
        p.legend_outside = true;
        f.xy_panels.push_back(std::move(p));
    }
    return f;
}

std::string report_html(const Result& r, const std::string& generated_utc, const std::string& program) {
    using plot::xml_escape;
    const auto value = [](const Value& v) {
        return std::isfinite(v.value) ? fmt::format("{:.1f} ± {:.1f}", v.value, v.U95) : std::string("–");
    };
    const auto range = [](const PartTeq& p) {
        return p.neutral ? fmt::format("{:.1f}–{:.1f}", p.neutral->cold_limit_c, p.neutral->warm_limit_c) : std::string("–");
    };
    const auto row = [&](const PartTeq& p, bool strong) {
        const std::string name = strong ? "<strong>" + xml_escape(p.name) + "</strong>" : xml_escape(p.name);
        return fmt::format("<tr><td>{}</td><td class=n>{}</td><td class=n>{:.2f}</td><td class=n>{:.1f}</td><td>{}</td><td>{}</td></tr>\n",
                           name, value(p.teq), p.skin_temp_c, p.q_w_m2, range(p), xml_escape(p.verdict));
    };
    std::string o;
    o += "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>Equivalent temperature: " + xml_escape(r.campaign) +
         "</title>\n<style>body{font:14px/1.35 sans-serif;margin:2em;max-width:60em}table{border-collapse:collapse;margin:.5em 0 1.5em}"
         "td,th{border-bottom:1px solid #ccc;padding:2px 8px;text-align:left}td.n{text-align:right;font-variant-numeric:tabular-nums}"
         ".warn{color:#a40}svg{max-width:100%;height:auto}</style></head><body>\n";
    o += "<h1>Equivalent temperature (ISO 14505-2)</h1>\n<table>\n";
    o += "<tr><th>campaign</th><td>" + xml_escape(r.campaign) + "</td></tr>\n";
    o += "<tr><th>calibration</th><td>" + xml_escape(r.calibration_campaign) + "</td></tr>\n";
    o += "<tr><th>method</th><td>teq = t<sub>sk</sub> − q / h<sub>cal</sub> per zone; regions and whole body as the uniform "
         "temperature in which they lose their zones' heat; h<sub>cal</sub> " +
         std::string(r.options.curved_h ? "read from the calibration's curve at each zone's own difference" : "constant") +
         "; 95 % intervals, Type A + B (GUM), " +
         std::to_string(r.options.monte_carlo_draws) + " Monte Carlo draws</td></tr>\n";
    o += "<tr><th>neutral ranges</th><td>" +
         (r.ranges.placeholder ? std::string("<span class=warn>placeholders 21–26 °C, not from a source</span>") : xml_escape(r.ranges.source)) +
         "</td></tr>\n";
    o += "<tr><th>written</th><td>" + xml_escape(generated_utc) + " by " + xml_escape(program) + "</td></tr>\n</table>\n";
    for (const auto& w : r.warnings) o += "<p class=warn>warning: " + xml_escape(w) + "</p>\n";
    const std::string head = "<table><tr><th>part</th><th>teq ± U95 (°C)</th><th>skin (°C)</th><th>q (W/m²)</th><th>neutral (°C)</th>"
                             "<th>verdict</th></tr>\n";
    for (const auto& c : r.cases) {
        o += fmt::format("<h2>Case {}</h2>\n<p>{} replicate{}; air {:.2f} °C, walls {:.2f} °C, air speed {:.2f} m/s (the probes' means)</p>\n",
                         c.case_id, c.replicates, c.replicates == 1 ? "" : "s", c.air_temp_c, c.wall_temp_c, c.air_speed_m_s);
        for (const auto& n : c.notes) o += "<p class=warn>note: " + xml_escape(n) + "</p>\n";
        o += head + row(c.whole_body, true);
        for (const auto& p : c.regions) o += row(p, false);
        o += "</table>\n";
    }
    o += "<h2>Comfort-zone diagram</h2>\n" + plot::to_svg(comfort_figure(r)) + "\n";
    for (const auto& c : r.cases) {
        o += fmt::format("<h2>Case {}: every zone</h2>\n", c.case_id) + head;
        for (const auto& p : c.zones) o += row(p, false);
        o += "</table>\n";
    }
    o += "</body></html>\n";
    return o;
}

}  // namespace manikind::analysis::teq
