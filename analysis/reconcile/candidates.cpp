#include "analysis/reconcile/candidates.hpp"

#include <cmath>

#include <fmt/core.h>

#include "physics/twin/twin.hpp"

namespace manikind::analysis::reconcile {

std::vector<physics::twin::Term> to_twin_terms(const std::vector<CandidateTerm>& terms, const std::vector<double>& values) {
    std::vector<physics::twin::Term> out;
    std::size_t k = 0;
    for (const auto& c : terms) {
        physics::twin::Term t;
        t.name = c.term;
        t.region = c.region;
        t.zones = c.zones;
        t.input = c.input;
        t.pattern = c.pattern;
        for (const auto& p : c.parameters) t.parameters[p.name] = values.at(k++);
        out.push_back(std::move(t));
    }
    return out;
}

std::vector<CandidateTerm> candidate_library(const std::vector<std::string>& wet_regions) {
    std::vector<CandidateTerm> lib = {
        {"humidity_buoyancy", "",
         "water vapour from wet skin lightens near-skin air, adding buoyancy: dT -> dT + gamma w dC (Eq. 7)",
         {{"gamma", "K m3/kg", 0.0, 400.0, 100.0, 0.0, 146.0, 40.0, 300.0}}, {}},
        {"diffusion_floor", "",
         "with opposing buoyancies cancelling, heat still diffuses: h_c -> h0 + A|.|^(1/4) (Eq. 5, Nu0)",
         {{"h0", "W/m2K", 0.0, 3.0, 0.3, 0.0, 0.3, 0.0, 1.5}}, {}},
        {"mixed_convection", "",
         "recorded air motion adds forced convection: h = (h_c^3 + (s 10.4 v^0.56)^3)^(1/3) (Eq. 9)",
         {{"scale", "", 0.0, 5.0, 1.0, 0.0, 1.0, 0.2, 3.0}}, {}},
        {"wall_offset", "",
         "the walls radiate at a temperature other than the recorded one (T_w + delta)",
         {{"delta_c", "degC", -10.0, 10.0, 0.5, 0.0, 0.0, -5.0, 5.0}}, {}},
        {"air_temp_bias", "",
         "the air probe reads the true air temperature plus a bias",
         {{"bias_c", "degC", -3.0, 3.0, 0.2, 0.0, 0.0, -0.2, 0.2}}, {}},  // EE181 +-0.2 degC (Table S2)
        {"textile_resistance", "",
         "the textile skin's resistance cools the evaporating surface: T_surface = T_skin - R q (Text S2.4)",
         {{"r_m2k_w", "m2K/W", 0.0, 0.05, 0.005, 0.0, 0.0054, 0.0, 0.03}}, {}},
    };
    for (const auto& region : wet_regions)
        lib.push_back({"partial_wettedness", region,
                       "part of this region is dry (e.g. clogged sweat pores): w -> f w there (Text S3.4)",
                       {{"fraction", "", 0.0, 1.0, 0.7, 1.0, std::nullopt, 0.02, 1.0}}, {}});
    return lib;
}

namespace {

struct InputInfo {
    const char* input;
    const char* unit;         // of the input
    const char* noun;         // what is off
    double span, start, plausible;  // fit bound, first guess, plausible bound (in the unit; per metre for height)
};

// Fit bounds: far beyond any chamber (a wall 15 K off, 1.5 kPa of vapour), so the fit is never
// held at a bound; plausible bounds are where a lab would start checking the set-up.
const std::vector<InputInfo>& input_info() {
    static const std::vector<InputInfo> info = {
        {"air_temp_c", "K", "air temperature", 10.0, 0.5, 3.0},
        {"wall_temp_c", "K", "radiant (wall) temperature", 15.0, 1.0, 8.0},
        {"vapour_pressure_pa", "Pa", "water-vapour pressure of the air", 1500.0, 100.0, 400.0},
        {"wettedness", "", "skin wettedness", 1.0, 0.2, 1.0},
        {"heat_flux_w_m2", "W/m2", "heat flux the sensors read", 30.0, 2.0, 10.0},
        // A fraction of the anemometer's reading (0.8/m: 1.8x at 1 m above the probe).
        {"air_speed_m_s", "", "air speed", 3.0, 0.2, 1.5},
    };
    return info;
}

const InputInfo& info_of(const std::string& input) {
    for (const auto& i : input_info())
        if (input == i.input) return i;
    return input_info().front();
}

}  // namespace

std::vector<CandidateTerm> generated_hypotheses(const GeometryKnown& g, bool all) {
    // The default pairings: the air stratifies with height; the surfaces the body sees differ
    // front, back, left, right and floor to ceiling (radiant asymmetry); the humidity probe
    // can be off, and humidity can stratify; one side of the skin can be drier. The rest of the
    // cross product (e.g. air temperature front to back, a flux offset by height) only with `all`.
    static const std::vector<std::pair<const char*, const char*>> pairings = {
        {"air_temp_c", "height"},         {"wall_temp_c", "front"},     {"wall_temp_c", "back"},
        {"wall_temp_c", "left"},          {"wall_temp_c", "right"},     {"wall_temp_c", "height"},
        {"vapour_pressure_pa", "uniform"}, {"vapour_pressure_pa", "height"}, {"wettedness", "left"},
        {"wettedness", "right"},      {"air_speed_m_s", "height"},
    };
    auto offered = [&](const std::string& input, const std::string& pattern) {
        if (pattern == "height" && !g.height) return false;
        if ((pattern == "front" || pattern == "back") && !g.facing) return false;
        if ((pattern == "left" || pattern == "right") && !g.sides) return false;
        if ((input == "vapour_pressure_pa" || input == "wettedness") && !g.wet) return false;
        // The air's speed by pattern matters only with forced convection, where air moves.
        if (input == "air_speed_m_s" && !g.air_moves) return false;
        // Uniform shifts of these are the named terms (air_temp_bias, wall_offset, partial
        // wettedness, a heat leak): the named one is offered, not its generated twin.
        // (a uniform air speed is mixed_convection's own scale: (1 + d)^0.56 times 10.4 v^0.56).
        if (pattern == "uniform" && input != "vapour_pressure_pa") return false;
        if (all) return true;
        for (const auto& [i, p] : pairings)
            if (input == i && pattern == p) return true;
        return false;
    };
    std::vector<CandidateTerm> out;
    for (const auto& info : input_info())
        for (const auto& pattern : physics::twin::pattern_names()) {
            if (!offered(info.input, pattern)) continue;
            const bool per_m = pattern == "height";
            CandidateTerm c;
            c.term = "input_pattern";
            c.input = info.input;
            c.pattern = pattern;
            c.rationale = fmt::format("the {} the zones meet differs {} from what the probes say", info.noun,
                                      per_m ? "with the zone's height" : pattern == "uniform" ? "uniformly" : "on the body's " + pattern);
            const std::string unit = std::string(info.unit) + (per_m ? "/m" : "");
            // Wettedness can only fall where the case is wet (1): its pattern runs -1..+0.5.
            const double lo = info.input == std::string("wettedness") ? -1.0 : -info.span;
            const double hi = info.input == std::string("wettedness") ? 0.5 : info.span;
            const double start = info.input == std::string("wettedness") ? -info.start : info.start;
            c.parameters = {{"value", unit, lo, hi, start, 0.0, std::nullopt, -info.plausible, info.plausible}};
            out.push_back(std::move(c));
        }
    return out;
}

std::string pattern_phrase(const CandidateTerm& c) {
    const bool wall = c.input == "wall_temp_c", air = c.input == "air_temp_c";
    if (c.pattern == "height")
        return air ? "a vertical air-temperature gradient" : wall ? "a floor-to-ceiling radiant gradient"
               : c.input == "vapour_pressure_pa" ? "humidity stratified with height" : "a pattern with height";
    if (wall) return "radiant asymmetry (" + c.pattern + ")";
    if (c.input == "vapour_pressure_pa" && c.pattern == "uniform") return "the humidity probe off";
    if (c.input == "wettedness") return "one side of the skin drier (" + c.pattern + ")";
    return c.input + " by " + c.pattern;
}

std::vector<std::string> plausibility_advice(const CandidateTerm& c, const std::vector<double>& v,
                                             const std::vector<double>& u) {
    std::vector<std::string> out;
    for (std::size_t i = 0; i < c.parameters.size() && i < v.size(); ++i) {
        const auto& p = c.parameters[i];
        const double ui = i < u.size() ? u[i] : 0.0;
        const bool unusual = v[i] < p.plausible_lo || v[i] > p.plausible_hi;
        if (c.term == "air_temp_bias" && unusual)
            out.push_back(fmt::format("the air temperature probe reads {:.2f} °C {}, beyond a calibrated EE181's "
                                      "±0.2 °C (Table S2): check the probe and its calibration",
                                      std::abs(v[i]), v[i] > 0 ? "high" : "low"));
        else if (c.term == "wall_offset" && unusual)
            out.push_back(fmt::format("the walls radiate {:+.1f} °C from the recorded wall temperature: check the wall "
                                      "thermocouples' contact and the enclosure lining's emissivity", v[i]));
        else if (unusual)
            out.push_back(fmt::format("{} = {:.4g} {} is unusual (expected {:g}..{:g}): check the set-up before "
                                      "trusting it", p.name, v[i], p.unit, p.plausible_lo, p.plausible_hi));
        else if (p.theory && std::isfinite(ui) && ui > 0.0 && std::abs(v[i] - *p.theory) > 3.0 * ui)
            out.push_back(fmt::format("{} = {:.4g} ± {:.2g} differs from the {:g} theory predicts", p.name, v[i], ui, *p.theory));
    }
    return out;
}

std::string plain_statement(const CandidateTerm& c, const std::vector<double>& v, const std::vector<double>& u) {
    if (c.term == "humidity_buoyancy") {
        const double theory = c.parameters[0].theory.value_or(146.0);
        const bool agrees = std::abs(v[0] - theory) <= 2.0 * u[0];
        return fmt::format("Humidity-driven buoyancy is missing from the twin: the recordings say the free-convection "
                           "drive is dT + {:.1f} (±{:.1f}) w dC, {} {:.0f} that beta_C alpha/(beta_T D) predicts. "
                           "Vapour from the wet skin lightens the near-skin air and, in hot air, opposes the downward "
                           "thermal plume.", v[0], u[0], agrees ? "consistent with the" : "not the", theory);
    }
    if (c.term == "diffusion_floor")
        return fmt::format("Heat leaves by diffusion even when the plume stalls: a floor h0 = {:.2f} (±{:.2f}) W/m2K "
                           "under the free-convection coefficient.", v[0], u[0]);
    if (c.term == "mixed_convection")
        return fmt::format("The recorded air motion matters: forced convection at {:.2f} (±{:.2f}) x de Dear's "
                           "10.4 v^0.56 blends with free convection (Eq. 9, n = 3).", v[0], u[0]);
    if (c.term == "wall_offset")
        return fmt::format("The enclosure walls radiate as if {:+.2f} (±{:.2f}) °C from the recorded wall "
                           "temperature: the wall sensor does not represent the radiating surfaces.", v[0], u[0]);
    if (c.term == "air_temp_bias")
        return fmt::format("The air-temperature probe reads {:+.2f} (±{:.2f}) °C from the true air temperature.",
                           v[0], u[0]);
    if (c.term == "textile_resistance")
        return fmt::format("The textile skin adds {:.4f} (±{:.4f}) m2K/W between the heated shell and the "
                           "evaporating surface, which runs cooler than the recorded skin temperature.", v[0], u[0]);
    if (c.term == "partial_wettedness")
        return fmt::format("Only {:.0f} % (±{:.0f} %) of the {} region is wet (e.g. clogged pores); the rest "
                           "evaporates nothing.", 100.0 * v[0], 100.0 * u[0], c.region);
    if (c.generated() && c.input == "air_speed_m_s") {
        const std::string size = fmt::format("{:+.2f} (±{:.2f})", v[0], u[0]);
        if (c.pattern == "height")
            return fmt::format("The air moves faster higher up: the speed a zone meets changes by {} of the anemometer's "
                               "reading per metre of height about the probe at 1.1 m (forced convection stronger at the "
                               "{}).", size, v[0] > 0 ? "head than at the feet" : "feet than at the head");
        return fmt::format("The air speed the zones meet differs by {} of the anemometer's reading ({}).", size,
                           c.pattern == "uniform" ? "everywhere" : "on the body's " + c.pattern);
    }
    if (c.generated()) {
        const auto& info = info_of(c.input);
        const std::string pm = info.unit;  // "per metre of height" is said in words
        const double ref_m = 1.1;  // the twin term's ref_height_m default: the probes' height
        const std::string size = c.input == "wettedness"
                                     ? fmt::format("{:+.2f} (±{:.2f})", v[0], u[0])
                                     : fmt::format("{:+.3g} (±{:.2g}) {}", v[0], u[0], pm);
        if (c.pattern == "height")
        {
            const bool temperature = std::string(info.unit) == "K";
            const char* floor_word = temperature ? (v[0] > 0 ? "colder" : "warmer") : (v[0] > 0 ? "less" : "more");
            return fmt::format("The {} rises by {} per metre of height about what the probe at {:.1f} m says ({}): "
                               "at the floor it is {:.3g} {} {}.",
                               info.noun, size, ref_m, pattern_phrase(c), std::abs(v[0]) * ref_m, info.unit, floor_word);
        }
        if (c.pattern == "uniform")
            return fmt::format("The {} is {} from what the probe says ({}).", info.noun, size, pattern_phrase(c));
        const std::string where = c.pattern == "front" ? "the front of the body faces" : c.pattern == "back" ? "the back of the body faces"
                                  : "the " + c.pattern + " side of the body meets";
        if (c.input == "wall_temp_c")
            return fmt::format("The surfaces {} radiate {} from the probed wall temperature ({}).", where, size, pattern_phrase(c));
        return fmt::format("The {} {} is {} from what the case's record says ({}).", info.noun,
                           c.pattern == "front" || c.pattern == "back" ? "on the body's " + c.pattern : "on the body's " + c.pattern + " side",
                           size, pattern_phrase(c));
    }
    return c.label();
}

}  // namespace manikind::analysis::reconcile
