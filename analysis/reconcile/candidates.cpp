#include "analysis/reconcile/candidates.hpp"

#include <cmath>

#include <fmt/core.h>

namespace manikind::analysis::reconcile {

std::vector<physics::twin::Term> to_twin_terms(const std::vector<CandidateTerm>& terms, const std::vector<double>& values) {
    std::vector<physics::twin::Term> out;
    std::size_t k = 0;
    for (const auto& c : terms) {
        physics::twin::Term t;
        t.name = c.term;
        t.region = c.region;
        t.zones = c.zones;
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
    return c.label();
}

}  // namespace manikind::analysis::reconcile
