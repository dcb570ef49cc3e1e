#include "physics/twin/twin.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "physics/constants.hpp"
#include "physics/convection.hpp"
#include "physics/heat_exchange.hpp"
#include "physics/psychrometrics.hpp"
#include "physics/range_check.hpp"

namespace manikind::physics::twin {
namespace {

// Parameters each term takes, with the value that leaves the baseline unchanged.
struct TermSpec {
    const char* name;
    std::vector<std::pair<const char*, double>> parameters;
};

const std::vector<TermSpec>& term_specs() {
    static const std::vector<TermSpec> specs = {
        {"humidity_buoyancy", {{"gamma", 0.0}}},          // dT -> dT + gamma w dC (Eq. 7)
        {"diffusion_floor", {{"h0", 0.0}}},               // h_c -> h0 + A |.|^(1/4) (Eq. 5/7)
        {"mixed_convection", {{"scale", 0.0}}},           // Eq. 9 with scale x 10.4 v^0.56
        {"wall_offset", {{"delta_c", 0.0}}},              // walls radiate at T_w + delta
        {"air_temp_bias", {{"bias_c", 0.0}}},             // probe reads T_true + bias
        {"textile_resistance", {{"r_m2k_w", 0.0}}},       // surface at T_s - R q (Text S2.4)
        {"partial_wettedness", {{"fraction", 1.0}}},      // w -> fraction w in one region
        {"heat_leak", {{"q_w_m2", 0.0}}},                 // a constant extra flux on some zones
        {"zone_gain", {{"gain", 0.0}}},                   // some zones' flux sensors read (1 + gain) q
        // A garment over one region (ISO 9920): intrinsic insulation, intrinsic evaporative
        // resistance and the clothing area factor.
        {"clothing", {{"icl_m2k_w", 0.0}, {"recl_m2kpa_w", 0.0}, {"fcl", 1.0}}},
        // One input off by a pattern over the body (issue 61): the input's value at a zone is
        // the recorded one plus value x the pattern's weight there (pattern_weight).
        {"input_pattern", {{"value", 0.0}, {"ref_height_m", 1.1}}},
    };
    return specs;
}

const TermSpec& spec_of(const std::string& name) {
    for (const auto& s : term_specs())
        if (name == s.name) return s;
    std::string known;
    for (const auto& s : term_specs()) known += std::string(known.empty() ? "" : ", ") + s.name;
    throw std::invalid_argument("unknown twin term '" + name + "' (known: " + known + ")");
}

double param(const Term& term, const char* key, double fallback) {
    const auto it = term.parameters.find(key);
    return it == term.parameters.end() ? fallback : it->second;
}

// The baseline constants by segment name without copying them (predict looks one up per zone).
const SegmentConstants* find_segment(const std::string& segment) {
    for (const auto& s : baseline_segments())  // the first letter and length before the whole name
        if (s.segment.size() == segment.size() && s.segment[0] == segment[0] && s.segment == segment) return &s;
    return nullptr;
}

// Saturation pressure, remembered per temperature on each thread: a trial's skin and air
// temperatures recur in every prediction of a campaign (exp and pow were an eighth of reconcile's
// time). The same function's value, so the same number; a temperature it refuses is not kept.
double saturation_pa(double temp_c) {
    struct Slot {
        double temp_c = std::numeric_limits<double>::quiet_NaN();  // NaN never matches
        double p_pa = 0.0;
    };
    constexpr std::size_t kSlots = 4096;
    thread_local std::array<Slot, kSlots> cache;
    const auto bits = std::bit_cast<std::uint64_t>(temp_c);
    Slot& slot = cache[static_cast<std::size_t>((bits * 0x9E3779B97F4A7C15ull) >> 52) % kSlots];
    if (slot.temp_c == temp_c) return slot.p_pa;
    const double p_pa = saturation_vapour_pressure_pa(temp_c);
    slot.temp_c = temp_c;
    slot.p_pa = p_pa;
    return p_pa;
}

}  // namespace

const std::vector<SegmentConstants>& baseline_segments() {
    // docs/twin-baseline.md steps 2 (A, Wissler / Table 2) and 3 (radiating area fraction f).
    static const std::vector<SegmentConstants> segments = {
        {"head", 2.6, 0.95},      {"chest", 1.5, 0.85},   {"back", 1.5, 0.85},  {"pelvis", 1.5, 0.60},
        {"upper_arm", 1.9, 0.70}, {"forearm", 1.9, 0.75}, {"hand", 2.7, 0.70},  {"thigh", 2.15, 0.70},
        {"calf", 2.15, 0.80},     {"foot", 1.57, 0.60},
    };
    return segments;
}

const std::vector<std::string>& input_names() {
    static const std::vector<std::string> names = {"air_temp_c", "wall_temp_c", "vapour_pressure_pa", "wettedness", "heat_flux_w_m2",
                                                   "air_speed_m_s"};
    return names;
}

const std::vector<std::string>& pattern_names() {
    static const std::vector<std::string> names = {"uniform", "height", "front", "back", "left", "right"};
    return names;
}

double pattern_weight(const std::string& pattern, const ZoneInput& zone, double ref_height_m) {
    if (pattern == "uniform") return 1.0;
    if (pattern == "height") {
        if (!zone.height_m) throw std::invalid_argument("zone " + std::to_string(zone.zone) + " has no height for a height pattern");
        return *zone.height_m - ref_height_m;  // per metre above the probe
    }
    if (pattern == "front") return zone.facing > 0 ? 1.0 : 0.0;
    if (pattern == "back") return zone.facing < 0 ? 1.0 : 0.0;
    if (pattern == "left") return zone.side < 0 ? 1.0 : 0.0;
    if (pattern == "right") return zone.side > 0 ? 1.0 : 0.0;
    throw std::invalid_argument("unknown pattern '" + pattern + "'");
}

std::optional<SegmentConstants> baseline_segment(const std::string& segment) {
    for (const auto& s : baseline_segments())
        if (s.segment == segment) return s;
    return std::nullopt;
}

void validate_term(const Term& term) {
    const TermSpec& spec = spec_of(term.name);
    for (const auto& [key, value] : term.parameters) {
        // `parameter = key`: clang 14 cannot capture a structured binding (the fuzz build uses clang).
        const bool known = std::any_of(spec.parameters.begin(), spec.parameters.end(),
                                       [&parameter = key](const auto& p) { return parameter == p.first; });
        if (!known) throw std::invalid_argument("twin term '" + term.name + "' has no parameter '" + key + "'");
        if (!std::isfinite(value)) throw std::invalid_argument("twin term '" + term.name + "': " + key + " is not finite");
    }
    if ((term.name == "partial_wettedness" || term.name == "clothing") && term.region.empty())
        throw std::invalid_argument("twin term '" + term.name + "' needs a region");
    if ((term.name == "heat_leak" || term.name == "zone_gain") && term.zones.empty())
        throw std::invalid_argument("twin term '" + term.name + "' needs zones");
    if (term.name == "input_pattern") {
        auto known = [](const std::vector<std::string>& names, const std::string& x) {
            return std::find(names.begin(), names.end(), x) != names.end();
        };
        auto listed = [](const std::vector<std::string>& names) {
            std::string out;
            for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
            return out;
        };
        if (!known(input_names(), term.input))
            throw std::invalid_argument("twin term 'input_pattern': unknown input '" + term.input + "' (known: " +
                                        listed(input_names()) + ")");
        if (!known(pattern_names(), term.pattern))
            throw std::invalid_argument("twin term 'input_pattern': unknown pattern '" + term.pattern + "' (known: " +
                                        listed(pattern_names()) + ")");
    }
}

ResolvedVersion resolve(const TwinVersion& v) {
    ResolvedVersion k;
    for (const Term& t : v.terms) {
        validate_term(t);
        if (t.name == "humidity_buoyancy") k.gamma = param(t, "gamma", 0.0);
        else if (t.name == "diffusion_floor") k.h0_w_m2k = param(t, "h0", 0.0);
        else if (t.name == "mixed_convection") k.forced_scale = param(t, "scale", 0.0);
        else if (t.name == "wall_offset") k.wall_offset_c = param(t, "delta_c", 0.0);
        else if (t.name == "air_temp_bias") k.air_bias_c = param(t, "bias_c", 0.0);
        else if (t.name == "textile_resistance") k.textile_r_m2k_w = param(t, "r_m2k_w", 0.0);
        else if (t.name == "partial_wettedness") k.wettedness_by_region.emplace_back(t.region, param(t, "fraction", 1.0));
        else if (t.name == "heat_leak") k.leaks.emplace_back(t.zones, param(t, "q_w_m2", 0.0));
        else if (t.name == "zone_gain") k.gains.emplace_back(t.zones, param(t, "gain", 0.0));
        else if (t.name == "clothing")
            k.garments.push_back({t.region, std::max(0.0, param(t, "icl_m2k_w", 0.0)), std::max(0.0, param(t, "recl_m2kpa_w", 0.0)),
                                  std::clamp(param(t, "fcl", 1.0), 1.0, 3.0)});
        else if (t.name == "input_pattern") {
            using P = ResolvedVersion::Pattern;
            P pt{t.input, t.pattern, param(t, "value", 0.0), param(t, "ref_height_m", 1.1)};
            pt.input_kind = t.input == "air_temp_c"           ? P::Input::air
                            : t.input == "wall_temp_c"        ? P::Input::wall
                            : t.input == "vapour_pressure_pa" ? P::Input::vapour
                            : t.input == "wettedness"         ? P::Input::wettedness
                            : t.input == "heat_flux_w_m2"     ? P::Input::heat_flux
                            : t.input == "air_speed_m_s"      ? P::Input::air_speed
                                                              : P::Input::other;
            pt.shape = t.pattern == "uniform"  ? P::Shape::uniform
                       : t.pattern == "height" ? P::Shape::height
                       : t.pattern == "front"  ? P::Shape::front
                       : t.pattern == "back"   ? P::Shape::back
                       : t.pattern == "left"   ? P::Shape::left
                       : t.pattern == "right"  ? P::Shape::right
                                               : P::Shape::other;
            k.patterns.push_back(std::move(pt));
        }
    }
    return k;
}

std::vector<ZoneFlux> predict(const TwinVersion& version, const TrialConditions& trial) {
    std::vector<ZoneFlux> out;
    predict(resolve(version), trial, out);
    return out;
}

void predict(const ResolvedVersion& k, const TrialConditions& trial, std::vector<ZoneFlux>& out, const std::vector<char>* only) {
    const double air_trial_c = trial.air_temp_c - k.air_bias_c;  // the probe read air + bias
    const double wall_trial_c = trial.wall_temp_c.value_or(trial.air_temp_c) + k.wall_offset_c;
    const double speed_m_s = std::max(0.0, trial.air_speed_m_s.value_or(0.0));
    require_in_range("relative humidity", trial.air_rh_pct, 0.0, 100.0, "%");  // as vapour_pressure_pa
    const double p_air_trial_pa = trial.air_rh_pct / 100.0 * saturation_pa(air_trial_c);
    const double c_air_trial_kg_m3 = vapour_concentration_kg_m3(p_air_trial_pa, air_trial_c);
    const double h_forced_w_m2k = k.forced_scale > 0.0 ? k.forced_scale * h_forced_de_dear_w_m2k(speed_m_s) : 0.0;

    if (!trial.zone_wettedness.empty() && trial.zone_wettedness.size() != trial.zones.size())
        throw std::invalid_argument("zone_wettedness: one value per zone, or none");
    if (only && only->size() != trial.zones.size()) throw std::invalid_argument("predict: one flag per zone");
    out.resize(trial.zones.size());
    for (std::size_t zi = 0; zi < trial.zones.size(); ++zi) {
        if (only && !(*only)[zi]) continue;
        const ZoneInput& z = trial.zones[zi];
        const SegmentConstants* seg = find_segment(z.segment);
        if (!seg) throw std::invalid_argument("zone " + std::to_string(z.zone) + ": unknown segment '" + z.segment + "'");
        double wettedness = trial.zone_wettedness.empty() ? trial.wettedness : std::clamp(trial.zone_wettedness[zi], 0.0, 1.0);
        for (const auto& [region, fraction] : k.wettedness_by_region)
            if (region == z.region) wettedness *= std::clamp(fraction, 0.0, 1.0);
        double leak_w_m2 = 0.0;
        for (const auto& [zones, q] : k.leaks)
            if (std::find(zones.begin(), zones.end(), z.zone) != zones.end()) leak_w_m2 += q;
        // The inputs as this zone meets them: the trial's, unless an input_pattern moves them
        // here (the air's absolute humidity stays the probe's unless vapour pressure is moved).
        double air_c = air_trial_c, wall_c = wall_trial_c, p_air_pa = p_air_trial_pa, c_air_kg_m3 = c_air_trial_kg_m3;
        double h_forced_zone_w_m2k = h_forced_w_m2k;
        if (!z.local.uniform()) {
            // A non-uniform room (LocalEnvironment): the zone's own air and radiant temperature, the
            // air's absolute humidity the probe's (the vapour spreads where the heat does not). A jet
            // at the zone is forced convection whatever the twin says of the room (de Dear's
            // coefficient, mixed with free convection as Eq. 9), scaled as mixed_convection scales it.
            air_c += z.local.air_offset_c;
            wall_c += z.local.radiant_offset_c;
            c_air_kg_m3 = vapour_concentration_kg_m3(p_air_pa, air_c);
            if (z.local.air_speed_m_s)
                h_forced_zone_w_m2k = (k.forced_scale > 0.0 ? k.forced_scale : 1.0) *
                                      h_forced_de_dear_w_m2k(std::max(0.0, *z.local.air_speed_m_s));
            leak_w_m2 += z.local.contact_w_m2 - z.local.solar_w_m2;
        }
        if (!k.patterns.empty()) {
            double speed_factor = 1.0;  // air_speed_m_s: relative to the anemometer's reading
            using P = ResolvedVersion::Pattern;
            for (const auto& pt : k.patterns) {
                double weight = 0.0;  // as pattern_weight, from the shape resolve() read
                switch (pt.shape) {
                    case P::Shape::uniform: weight = 1.0; break;
                    case P::Shape::front: weight = z.facing > 0 ? 1.0 : 0.0; break;
                    case P::Shape::back: weight = z.facing < 0 ? 1.0 : 0.0; break;
                    case P::Shape::left: weight = z.side < 0 ? 1.0 : 0.0; break;
                    case P::Shape::right: weight = z.side > 0 ? 1.0 : 0.0; break;
                    default: weight = pattern_weight(pt.pattern, z, pt.ref_height_m);  // height: checks the zone has one
                }
                const double d = pt.value * weight;
                switch (pt.input_kind) {
                    case P::Input::air: air_c += d; break;
                    case P::Input::wall: wall_c += d; break;
                    case P::Input::vapour: p_air_pa = std::max(0.0, p_air_pa + d); break;
                    case P::Input::wettedness: wettedness = wettedness > 0.0 ? std::clamp(wettedness + d, 0.0, 1.0) : 0.0; break;
                    case P::Input::heat_flux: leak_w_m2 += d; break;  // what the sensor adds
                    case P::Input::air_speed: speed_factor += d; break;
                    case P::Input::other: break;
                }
            }
            c_air_kg_m3 = vapour_concentration_kg_m3(p_air_pa, air_c);
            // The air a zone meets moves speed_factor times what the anemometer reads; it matters
            // only where forced convection is in the twin (mixed_convection).
            if (speed_factor != 1.0 && k.forced_scale > 0.0)
                h_forced_zone_w_m2k = k.forced_scale * h_forced_de_dear_w_m2k(std::max(0.0, z.local.air_speed_m_s.value_or(speed_m_s) * speed_factor));
        }

        // Fluxes from an exchange surface at surface_c (the textile, when it has resistance).
        auto fluxes_at = [&](double surface_c) {
            ZoneFlux f;
            f.zone = z.zone;
            f.surface_temp_c = surface_c;
            const double dt_c = surface_c - air_c;
            // One saturation pressure per surface temperature serves both the concentration and
            // Eq. 1 (reconcile evaluates this thousands of times per campaign).
            const double p_surface_pa = saturation_pa(surface_c);
            const double dc_kg_m3 = vapour_concentration_kg_m3(p_surface_pa, surface_c) - c_air_kg_m3;
            const double drive_c = dt_c + k.gamma * wettedness * dc_kg_m3;  // Eq. 7 with omega
            double h = k.h0_w_m2k + seg->wissler_a * std::sqrt(std::sqrt(std::abs(drive_c)));  // |.|^(1/4)
            if (h_forced_zone_w_m2k > 0.0) h = h_mixed_w_m2k(h, h_forced_zone_w_m2k);  // Eq. 9, n = 3
            f.h_c_w_m2k = h;
            f.q_convection_w_m2 = h * dt_c;
            f.q_radiation_w_m2 = radiative_heat_flux_w_m2(surface_c, wall_c, baseline_skin_emissivity, seg->radiating_fraction);
            // Eq. 1; no condensation modelled (docs/twin-baseline.md step 4).
            f.q_evaporation_w_m2 = p_surface_pa > p_air_pa
                                       ? evaporative_heat_flux_w_m2(h, p_surface_pa, p_air_pa, wettedness, baseline_lewis_k_kpa)
                                       : 0.0;
            f.q_other_w_m2 = leak_w_m2;
            f.q_total_w_m2 = f.q_convection_w_m2 + f.q_radiation_w_m2 + f.q_evaporation_w_m2 + f.q_other_w_m2;
            return f;
        };

        const ResolvedVersion::Garment* garment = nullptr;
        for (const auto& g : k.garments)
            if (g.region == z.region) garment = &g;
        ZoneFlux f = fluxes_at(z.skin_temp_c);
        const bool clothed = garment && (garment->icl_m2k_w > 0.0 || garment->recl_m2kpa_w > 0.0);
        if (clothed) {
            // Clothed (ISO 9920): the garment's outer surface, fcl times the skin's area, exchanges
            // with the room as a bare surface would; the skin reaches it through Icl. Dry: the
            // surface temperature T_cl where (T_s - T_cl)/Icl = fcl q_dry(T_cl) (bisection: the
            // left side falls and the right side rises with T_cl). Evaporation: through Recl in
            // series with the outer boundary layer, q_e = w (p_s - p_a) / (Recl + 1/(fcl LR h_c)).
            const double icl = std::max(garment->icl_m2k_w, 1e-6), fcl = garment->fcl;
            auto dry_out = [&](double t) {
                const ZoneFlux o = fluxes_at(t);
                return o.q_convection_w_m2 + o.q_radiation_w_m2;
            };
            double lo = std::min(z.skin_temp_c, air_c) - 40.0, hi = std::max(z.skin_temp_c, air_c) + 40.0;
            for (int i = 0; i < 40; ++i) {  // 120 K / 2^40: far below any sensor
                const double mid = 0.5 * (lo + hi);
                ((z.skin_temp_c - mid) / icl - fcl * dry_out(mid) > 0.0 ? lo : hi) = mid;
            }
            const double t_cl = 0.5 * (lo + hi);
            ZoneFlux c = fluxes_at(t_cl);
            f = ZoneFlux{};
            f.zone = z.zone;
            f.surface_temp_c = t_cl;
            f.h_c_w_m2k = c.h_c_w_m2k;
            f.q_convection_w_m2 = fcl * c.q_convection_w_m2;
            f.q_radiation_w_m2 = fcl * c.q_radiation_w_m2;
            const double p_skin_pa = saturation_pa(z.skin_temp_c);
            const double h_e = baseline_lewis_k_kpa * std::max(c.h_c_w_m2k, 1e-9);  // W/m²kPa
            f.q_evaporation_w_m2 = p_skin_pa > p_air_pa
                                       ? wettedness * (p_skin_pa - p_air_pa) / 1000.0 / (garment->recl_m2kpa_w + 1.0 / (fcl * h_e))
                                       : 0.0;
            f.q_other_w_m2 = leak_w_m2;
            f.q_total_w_m2 = f.q_convection_w_m2 + f.q_radiation_w_m2 + f.q_evaporation_w_m2 + f.q_other_w_m2;
        }
        // The textile skin is worn only for the wet trials (the paper's Fig. 1A inset, Text S3):
        // a dry trial's surface is the manikin's own shell.
        // Metered sweat (zone_wettedness) is worn on the textile skin too.
        if (!clothed && k.textile_r_m2k_w > 0.0 && (trial.wettedness > 0.0 || !trial.zone_wettedness.empty())) {
            // Surface temperature: root of g(T) = T - T_s + R q(T). q rises with T, so g' > 1 and
            // Newton (secant derivative) converges in a few steps; kept within ±30 K of the skin.
            const double r = k.textile_r_m2k_w;
            double surface_c = z.skin_temp_c;
            double g = r * (f.q_total_w_m2 - f.q_other_w_m2);
            for (int i = 0; i < 20 && std::abs(g) > 1e-9; ++i) {
                const double probe_c = surface_c + 1e-4;
                const ZoneFlux fp = fluxes_at(probe_c);
                const double g_probe = probe_c - z.skin_temp_c + r * (fp.q_total_w_m2 - fp.q_other_w_m2);
                const double slope = std::max((g_probe - g) / 1e-4, 1.0);
                surface_c = std::clamp(surface_c - g / slope, z.skin_temp_c - 30.0, z.skin_temp_c + 30.0);
                f = fluxes_at(surface_c);
                g = surface_c - z.skin_temp_c + r * (f.q_total_w_m2 - f.q_other_w_m2);
            }
        }
        // A sensor's gain error scales what it reads, whatever the physics behind it.
        for (const auto& [zones, gain] : k.gains)
            if (std::find(zones.begin(), zones.end(), z.zone) != zones.end()) {
                f.q_convection_w_m2 *= 1.0 + gain;
                f.q_radiation_w_m2 *= 1.0 + gain;
                f.q_evaporation_w_m2 *= 1.0 + gain;
                f.q_other_w_m2 *= 1.0 + gain;
                f.q_total_w_m2 *= 1.0 + gain;
            }
        out[zi] = f;
    }
}

double area_weighted_mean_w_m2(const std::vector<ZoneFlux>& fluxes, const std::vector<ZoneInput>& zones,
                               const std::vector<int>& zone_ids) {
    double sum = 0.0, area = 0.0;
    for (std::size_t i = 0; i < fluxes.size() && i < zones.size(); ++i) {
        if (std::find(zone_ids.begin(), zone_ids.end(), zones[i].zone) == zone_ids.end()) continue;
        sum += fluxes[i].q_total_w_m2 * zones[i].area_m2;
        area += zones[i].area_m2;
    }
    return area > 0.0 ? sum / area : 0.0;
}

}  // namespace manikind::physics::twin
