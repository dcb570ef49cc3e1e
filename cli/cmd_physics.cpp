// `manikin physics ...`: the physics library at the command line, one correlation at a time.
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "analysis/reconcile/cfd_forms.hpp"
#include "cli/commands.hpp"
#include "cli/report.hpp"
#include "base/user_error.hpp"
#include "physics/air_properties.hpp"
#include "physics/buoyancy.hpp"
#include "physics/convection.hpp"
#include "physics/heat_exchange.hpp"
#include "physics/paper_cfd_table.hpp"
#include "physics/psychrometrics.hpp"
#include "physics/range_check.hpp"
#include "physics/sign_convention.hpp"
#include "physics/threshold_map.hpp"

namespace manikind::cli {
namespace {

namespace ph = manikind::physics;

struct StateOptions {
    double air_temp_c = 35.0;
    double rh_pct = 50.0;
    double skin_temp_c = 35.0;
    double wettedness = 1.0;
    double length_m = 1.8;
    bool json = false;
};

void add_state_options(CLI::App* cmd, StateOptions& o, bool with_air = true) {
    if (with_air) {
        cmd->add_option("--air-temp", o.air_temp_c, "Far-field air temperature, °C")->required();
        cmd->add_option("--rh", o.rh_pct, "Far-field relative humidity, % (0-100)")->required();
    }
    cmd->add_option("--skin-temp", o.skin_temp_c, "Skin (surface) temperature, °C")->capture_default_str();
    cmd->add_option("--wettedness", o.wettedness, "Skin wettedness: 0 dry, 1 water-saturated")->capture_default_str();
    cmd->add_option("--length", o.length_m, "Characteristic length for Ra, m (manikin height)")->capture_default_str();
    cmd->add_flag("--json", o.json, "Print one JSON object instead of a table");
}

ph::SkinAirState to_state(const StateOptions& o) {
    ph::SkinAirState s;
    s.skin_temp_c = o.skin_temp_c;
    s.air_temp_c = o.air_temp_c;
    s.air_rh_pct = o.rh_pct;
    s.skin_wettedness = o.wettedness;
    s.characteristic_length_m = o.length_m;
    return s;
}

// Non-physical inputs are errors; inputs outside a correlation's range are warnings.
void validate_state(const StateOptions& o, Report& report);

template <typename F>
auto physics_call(F&& f) {
    try {
        return f();
    } catch (const std::domain_error& e) {
        throw UserError(e.what());
    }
}

void validate_state(const StateOptions& o, Report& report) {
    physics_call([&] {
        ph::require_in_range("--rh", o.rh_pct, 0.0, 100.0, "%");
        ph::require_in_range("--air-temp", o.air_temp_c, -40.0, 100.0, "°C");
        ph::require_in_range("--skin-temp", o.skin_temp_c, -40.0, 100.0, "°C");
        ph::require_in_range("--wettedness", o.wettedness, 0.0, 1.0, "");
        ph::require_in_range("--length", o.length_m, 0.01, 10.0, "m");
        return 0;
    });
    if (o.air_temp_c < 20.0 || o.air_temp_c > 50.0)
        report.warn(fmt::format("air temperature {} °C is outside 20..50 °C, the range of the paper's CFD "
                                "study behind Eq. 8 and Table 1", o.air_temp_c));
}

// --model grammar: eq8 | dt-only | eq5 | laminar | turbulent | table1:<segment> |
// table2:<stolwijk|jos|wissler|present|seed>:<region> | posture:<standing|seated|supine>
struct FreeModel {
    std::string description;
    double h_w_m2k = 0.0;
    std::optional<ph::Region> region;  // for the regional forced coefficient
};

FreeModel evaluate_model(const std::string& model, const ph::BuoyancyResult& b) {
    const double k = ph::air_properties(b.film_temp_c).properties.conductivity_w_m_k;
    if (model == "eq8") return {"Eq. 8: 0.3 + 1.25 |dT + 146 dC|^(1/4)", ph::h_eq8_w_m2k(b.dt_c, b.dc_kg_m3), {}};
    if (model == "dt-only") return {"Eq. S8: 1.36 |dT|^0.3", ph::h_dt_only_w_m2k(b.dt_c), {}};
    if (model == "eq5")
        return {"Eq. 5: Nu = 17.27 + 0.574 |Ra_T|^(1/4), h = Nu k / L",
                ph::h_from_nusselt_w_m2k(ph::nusselt_eq5(b.ra_total), k), {}};
    if (model == "laminar")
        return {"Eq. 3: Nu = 0.59 |Ra_T|^(1/4)", ph::h_from_nusselt_w_m2k(ph::nusselt_vertical_plate_laminar(b.ra_total), k), {}};
    if (model == "turbulent")
        return {"Eq. 4: Nu = 0.1 |Ra_T|^(1/3)", ph::h_from_nusselt_w_m2k(ph::nusselt_vertical_plate_turbulent(b.ra_total), k), {}};
    const auto colon = model.find(':');
    const std::string family = model.substr(0, colon);
    const std::string rest = colon == std::string::npos ? "" : model.substr(colon + 1);
    if (family == "table1") {
        const auto seg = ph::parse_segment(rest);
        if (!seg) throw UserError(fmt::format("--model table1:{}: unknown segment; expected one of head, chest, back, "
                                              "whole_torso, upper_arm, forearm, whole_arm, pelvis, thigh, calf, "
                                              "whole_leg, foot, hand", rest));
        std::string note = fmt::format("Table 1 ({}): h0 + B(sign of N) |dT + 146 dC|^(1/4)", rest);
        if (!ph::segment_coefficients(*seg).b_neg_printed && ph::buoyancy_drive_c(b.dt_c, b.dc_kg_m3) < 0.0)
            note += " [Table 1 prints no N<0 fit for the chest: whole-torso B used]";
        return {note, ph::h_segment_w_m2k(*seg, b.dt_c, b.dc_kg_m3), {}};
    }
    if (family == "table2") {
        const auto colon2 = rest.find(':');
        const auto which = ph::parse_regional_model(rest.substr(0, colon2));
        const auto region = colon2 == std::string::npos ? std::nullopt : ph::parse_region(rest.substr(colon2 + 1));
        if (!which || !region)
            throw UserError(fmt::format("--model {}: expected table2:<stolwijk|jos|wissler|present|seed>:"
                                        "<head|torso|arms|hands|legs|feet>", model));
        return {fmt::format("Table 2 ({})", rest), ph::h_regional_w_m2k(*which, *region, b.dt_c, b.dc_kg_m3), region};
    }
    if (family == "posture") {
        const auto posture = ph::parse_posture(rest);
        if (!posture) throw UserError(fmt::format("--model {}: expected posture:<standing|seated|supine>", model));
        return {fmt::format("Text S6.2 ({}, dry-skin fit)", rest), ph::h_posture_w_m2k(*posture, b.dt_c), {}};
    }
    throw UserError(fmt::format("--model {}: unknown; expected eq8, dt-only, eq5, laminar, turbulent, "
                                "table1:<segment>, table2:<model>:<region> or posture:<name>", model));
}

void add_psychro(CLI::App& physics) {
    auto o = std::make_shared<StateOptions>();
    auto* cmd = physics.add_subcommand("psychro", "Moist-air state: p_sat, vapour pressure and concentration, density, humidity ratio");
    cmd->add_option("--temp", o->air_temp_c, "Air temperature, °C")->required();
    cmd->add_option("--rh", o->rh_pct, "Relative humidity, % (0-100)")->required();
    cmd->add_flag("--json", o->json, "Print one JSON object");
    cmd->footer("Example: manikin physics psychro --temp 35 --rh 10");
    cmd->callback([o] {
        Report r(fmt::format("Moist air at {} °C, {} % RH", o->air_temp_c, o->rh_pct));
        physics_call([&] {
            const double p_sat = ph::saturation_vapour_pressure_pa(o->air_temp_c);
            const double p_v = ph::vapour_pressure_pa(o->air_temp_c, o->rh_pct);
            if (o->air_temp_c < 0.0 || o->air_temp_c > 100.0)
                r.warn("the seed p_sat formula is checked over 0..100 °C (liquid water) only");
            r.add("saturation_vapour_pressure_pa", "saturation vapour pressure", p_sat, "Pa", 1);
            r.add("vapour_pressure_pa", "vapour pressure", p_v, "Pa", 1);
            r.add("vapour_concentration_kg_m3", "vapour concentration", ph::vapour_concentration_kg_m3(p_v, o->air_temp_c), "kg/m³", 5);
            r.add("density_kg_m3", "moist-air density", ph::moist_air_density_kg_m3(o->air_temp_c, p_v), "kg/m³", 4);
            r.add("humidity_ratio_kg_kg", "humidity ratio", ph::humidity_ratio_kg_kg(p_v), "kg/kg", 5);
            return 0;
        });
        r.print(o->json);
    });
}

void add_buoyancy(CLI::App& physics) {
    auto o = std::make_shared<StateOptions>();
    auto* cmd = physics.add_subcommand("buoyancy", "Thermal and humidity buoyancy near the skin, Rayleigh numbers (Eq. 2)");
    add_state_options(cmd, *o);
    cmd->footer("Positive buoyancy = near-skin air lighter than the room (rising plume).\n"
                "Example: manikin physics buoyancy --air-temp 41 --rh 10 --skin-temp 35");
    cmd->callback([o] {
        Report r(fmt::format("Buoyancy: skin {} °C (wettedness {}), air {} °C / {} % RH", o->skin_temp_c, o->wettedness,
                             o->air_temp_c, o->rh_pct));
        validate_state(*o, r);
        const auto b = physics_call([&] { return ph::buoyancy(to_state(*o)); });
        r.warn_all(b.warnings);
        r.add("dt_c", "dT = T_skin - T_air", b.dt_c, "°C", 2);
        r.add("dc_kg_m3", "dC = C_skin - C_air", b.dc_kg_m3, "kg/m³", 5);
        r.add("film_temp_c", "film temperature", b.film_temp_c, "°C", 2);
        r.add("film_density_kg_m3", "film density", b.film_density_kg_m3, "kg/m³", 4);
        r.add("beta_t_1_k", "beta_T", b.beta_t_1_k, "1/K", 6);
        r.add("beta_c_m3_kg", "beta_C = 0.607/rho", b.beta_c_m3_kg, "m³/kg", 4);
        r.add("b_dt_n_m3", "B_dT", b.b_dt_n_m3, "N/m³", 4);
        r.add("b_dc_n_m3", "B_dC", b.b_dc_n_m3, "N/m³", 4);
        r.add("b_net_n_m3", "B_net", b.b_net_n_m3, "N/m³", 4);
        r.add("ra_dt", "Ra_dT", b.ra_dt, "");
        r.add("ra_dc", "Ra_dC", b.ra_dc, "");
        r.add("ra_total", "Ra_T (Eq. 2)", b.ra_total, "");
        r.add("coupling_coefficient", "beta_C alpha/(beta_T D)", b.coupling_coefficient, "K m³/kg", 1);
        r.add("buoyancy_drive_c", "N = dT + 146 dC", ph::buoyancy_drive_c(b.dt_c, b.dc_kg_m3), "°C", 3);
        r.add_text("plume", "plume", b.b_net_n_m3 > 0.0 ? "ascending" : b.b_net_n_m3 < 0.0 ? "descending" : "stagnant");
        r.print(o->json);
    });
}

void add_h_c(CLI::App& physics) {
    auto o = std::make_shared<StateOptions>();
    auto model = std::make_shared<std::string>("eq8");
    auto speed = std::make_shared<double>(0.0);
    auto* cmd = physics.add_subcommand("h-c", "Free (and optionally mixed) convection coefficient, with the fluxes it implies");
    add_state_options(cmd, *o);
    cmd->add_option("--model", *model,
                    "eq8 | dt-only | eq5 | laminar | turbulent | table1:<segment> | "
                    "table2:<stolwijk|jos|wissler|present|seed>:<region> | posture:<standing|seated|supine>")
        ->capture_default_str();
    cmd->add_option("--air-speed", *speed, "Air speed, m/s: adds forced (de Dear) and mixed (Eq. 9, n = 3) coefficients");
    cmd->footer(std::string("Heat fluxes: ") + ph::heat_flux_sign + ".\n"
                "Examples:\n  manikin physics h-c --air-temp 41 --rh 10 --skin-temp 35\n"
                "  manikin physics h-c --air-temp 41 --rh 10 --model table1:thigh --json\n"
                "  manikin physics h-c --air-temp 41 --rh 20 --model table2:wissler:legs --air-speed 0.1");
    cmd->callback([o, model, speed, cmd] {
        Report r(fmt::format("Convection: skin {} °C (wettedness {}), air {} °C / {} % RH", o->skin_temp_c,
                             o->wettedness, o->air_temp_c, o->rh_pct));
        validate_state(*o, r);
        const auto b = physics_call([&] { return ph::buoyancy(to_state(*o)); });
        r.warn_all(b.warnings);
        const FreeModel m = physics_call([&] { return evaluate_model(*model, b); });
        r.add_text("model", "model", m.description);
        r.add("dt_c", "dT = T_skin - T_air", b.dt_c, "°C", 2);
        r.add("dc_kg_m3", "dC (x wettedness)", b.dc_kg_m3, "kg/m³", 5);
        r.add("buoyancy_drive_c", "N = dT + 146 dC", ph::buoyancy_drive_c(b.dt_c, b.dc_kg_m3), "°C", 3);
        r.add("h_c_w_m2k", "h_c (free)", m.h_w_m2k, "W/m²K");
        double h_w_m2k = m.h_w_m2k;
        if (cmd->count("--air-speed") > 0) {
            if (!std::isfinite(*speed) || *speed < 0.0)
                throw UserError(fmt::format("--air-speed = {} m/s: expected a speed >= 0", *speed));
            const double h_f = m.region ? ph::h_forced_regional_w_m2k(*m.region, *speed) : ph::h_forced_de_dear_w_m2k(*speed);
            if (*speed < 0.2) r.warn("de Dear's forced correlation is not validated below 0.2 m/s (Discussion)");
            h_w_m2k = ph::h_mixed_w_m2k(m.h_w_m2k, h_f);
            r.add("h_forced_w_m2k", m.region ? "h_F (MATLAB regional fit)" : "h_F = 10.4 v^0.56", h_f, "W/m²K");
            r.add("h_mixed_w_m2k", "h_mix (Eq. 9, n = 3, assisting)", h_w_m2k, "W/m²K");
        }
        const double p_skin = physics_call([&] { return ph::saturation_vapour_pressure_pa(o->skin_temp_c); });
        const double p_air = physics_call([&] { return ph::vapour_pressure_pa(o->air_temp_c, o->rh_pct); });
        r.add_text("heat_flux_sign", "heat flux", ph::heat_flux_sign);
        r.add("q_convection_w_m2", "q_conv = h (T_skin - T_air)", h_w_m2k * b.dt_c, "W/m²", 2);
        r.add("q_evaporation_w_m2", "q_evap = w 16.5 h dp (Eq. 1)",
              ph::evaporative_heat_flux_w_m2(h_w_m2k, p_skin, p_air, o->wettedness), "W/m²", 2);
        r.print(o->json);
    });
}

void add_stagnation(CLI::App& physics) {
    auto o = std::make_shared<StateOptions>();
    auto* cmd = physics.add_subcommand("stagnation", "Air temperature at which thermal and humidity buoyancy cancel (Table S4)");
    cmd->add_option("--rh", o->rh_pct, "Air relative humidity, % (0-100)")->required();
    add_state_options(cmd, *o, false);
    cmd->footer("Example: manikin physics stagnation --rh 10   (41 °C for a 35 °C wet skin, Introduction)");
    cmd->callback([o] {
        Report r(fmt::format("Stagnation: skin {} °C (wettedness {}), {} % RH", o->skin_temp_c, o->wettedness, o->rh_pct));
        o->air_temp_c = o->skin_temp_c;
        validate_state(*o, r);
        const auto t = physics_call([&] { return ph::stagnation_air_temp_c(o->rh_pct, o->skin_temp_c, o->wettedness); });
        if (!t)
            throw UserError(fmt::format("no stagnation temperature between {} and {} °C at {} % RH: humidity "
                                        "buoyancy never balances thermal buoyancy (e.g. saturated or dry skin)",
                                        o->skin_temp_c, o->skin_temp_c + 40.0, o->rh_pct));
        r.add("stagnation_air_temp_c", "stagnation air temperature", *t, "°C", 2);
        r.add("dt_c", "dT = T_skin - T_air there", o->skin_temp_c - *t, "°C", 2);
        r.print(o->json);
    });
}

void add_threshold(CLI::App& physics) {
    auto o = std::make_shared<StateOptions>();
    auto ratio = std::make_shared<double>(1.05);
    auto law = std::make_shared<std::string>("eq8");
    auto grid = std::make_shared<bool>(false);
    auto grid_spec = std::make_shared<ph::ThresholdGrid>();
    auto* cmd = physics.add_subcommand("threshold-speed", "Air speed above which forced convection dominates mixed (Fig. 3C)");
    cmd->add_option("--air-temp", o->air_temp_c, "Air temperature, °C (single point)");
    cmd->add_option("--rh", o->rh_pct, "Relative humidity, % (single point)");
    cmd->add_option("--skin-temp", o->skin_temp_c, "Wet skin temperature, °C")->capture_default_str();
    cmd->add_option("--ratio", *ratio, "Criterion h_mix/h_F <= ratio (paper: 1.05 or 1.1)")->capture_default_str();
    cmd->add_option("--law", *law, "Free convection law: eq8 (temperature + humidity) or dt-only (Eq. S8)")->capture_default_str();
    cmd->add_flag("--grid", *grid, "Search a T x RH grid for the minimum threshold instead of one point");
    cmd->add_option("--t-step", grid_spec->air_temp_step_c, "Grid step in air temperature, °C")->capture_default_str();
    cmd->add_option("--rh-step", grid_spec->rh_step_pct, "Grid step in RH, %")->capture_default_str();
    cmd->add_flag("--json", o->json, "Print one JSON object");
    cmd->footer("Examples:\n  manikin physics threshold-speed --air-temp 41 --rh 10\n"
                "  manikin physics threshold-speed --grid            (minimum over 20-50 °C x 10-90 %, 1 °C x 10 %)");
    cmd->callback([o, ratio, law, grid, grid_spec, cmd] {
        if (*law != "eq8" && *law != "dt-only") throw UserError(fmt::format("--law {}: expected eq8 or dt-only", *law));
        if (*ratio <= 1.0 || *ratio > 2.0) throw UserError(fmt::format("--ratio {}: expected 1 < ratio <= 2", *ratio));
        const auto which = *law == "eq8" ? ph::FreeConvectionLaw::eq8 : ph::FreeConvectionLaw::dt_only;
        Report r(fmt::format("Threshold air speed, h_mix/h_F <= {} ({})", *ratio, *law));
        r.add("max_free_to_forced_ratio", "h_c/h_F at most", ph::max_free_to_forced_ratio(*ratio), "", 3);
        ph::ThresholdPoint p;
        if (*grid) {
            if (grid_spec->air_temp_step_c <= 0.0 || grid_spec->rh_step_pct <= 0.0)
                throw UserError("--t-step and --rh-step must be positive");
            grid_spec->skin_temp_c = o->skin_temp_c;
            grid_spec->mix_to_forced_ratio = *ratio;
            grid_spec->law = which;
            p = physics_call([&] { return ph::minimum_threshold_on_grid(*grid_spec); });
            r.add_text("search", "search", fmt::format("minimum over {}-{} °C x {}-{} % RH, steps {} °C x {} %",
                                                      grid_spec->air_temp_min_c, grid_spec->air_temp_max_c,
                                                      grid_spec->rh_min_pct, grid_spec->rh_max_pct,
                                                      grid_spec->air_temp_step_c, grid_spec->rh_step_pct));
        } else {
            if (cmd->count("--air-temp") == 0 || cmd->count("--rh") == 0)
                throw UserError("give --air-temp and --rh for one point, or --grid to search the T x RH grid");
            validate_state(*o, r);
            p = physics_call([&] { return ph::threshold_point(o->air_temp_c, o->rh_pct, o->skin_temp_c, *ratio, which); });
        }
        r.add("air_temp_c", "air temperature", p.air_temp_c, "°C", 1);
        r.add("air_rh_pct", "relative humidity", p.air_rh_pct, "%", 1);
        r.add("h_c_w_m2k", "h_c (free)", p.h_free_w_m2k, "W/m²K");
        r.add("threshold_speed_m_s", "threshold air speed", p.speed_m_s, "m/s", 4);
        r.print(o->json);
    });
}

void add_cfd_gamma(CLI::App& physics) {
    auto json = std::make_shared<bool>(false);
    auto* cmd = physics.add_subcommand(
        "cfd-gamma", "Fit gamma in |dT + gamma dC| to the paper's CFD whole-body h (Tables S8-S10): Eq. 7 and Eq. S8 shapes");
    cmd->add_flag("--json", *json, "Print one JSON object instead of a table");
    cmd->footer("Forms: Eq. 7 h0 + B |N|^(1/4) (h0, B, gamma free); Eq. S8 shape a |N|^0.3 (a, gamma free);\n"
                "N = dT + gamma dC. Weightings: u = 5 % of h; equal u (5 % of mean h); log residuals (5 %).\n"
                "Standard errors from the Jacobian, x sqrt(chi2/dof) when > 1; combined u = sqrt(mean se^2 + var between fits).\n"
                "Example: manikin physics cfd-gamma --json");
    cmd->callback([json] {
        namespace rc = manikind::analysis::reconcile;
        std::vector<rc::CfdHObservation> obs;
        for (const auto& c : ph::paper_cfd_cases())
            obs.push_back({c.case_id, c.air_temp_c, c.air_rh_pct, ph::cfd_skin_temp_c, c.h_sim_w_m2k});
        const auto r = rc::fit_cfd_gamma_forms(obs);
        const auto fit_json = [](const rc::CfdFormFit& f) {
            return nlohmann::json{{"form", rc::to_string(f.form)},
                                  {"weighting", rc::to_string(f.weighting)},
                                  {"exponent", f.exponent},
                                  {"gamma_k_m3_kg", f.gamma_k_m3_kg},
                                  {"gamma_se_k_m3_kg", f.gamma_se_k_m3_kg},
                                  {"gamma_profile_lo_k_m3_kg", f.gamma_profile_lo_k_m3_kg},
                                  {"gamma_profile_hi_k_m3_kg", f.gamma_profile_hi_k_m3_kg},
                                  {"h0_w_m2k", f.h0_w_m2k},
                                  {"h0_se_w_m2k", f.h0_se_w_m2k},
                                  {"b_w_m2k", f.b_w_m2k},
                                  {"b_se_w_m2k", f.b_se_w_m2k},
                                  {"rmse_w_m2k", f.rmse_w_m2k},
                                  {"rmse_pct", f.rmse_pct},
                                  {"chi2_per_dof", f.chi2_per_dof},
                                  {"dof", f.dof},
                                  {"converged", f.converged},
                                  {"at_bound", f.at_bound}};
        };
        const auto fixed_json = [](const rc::CfdFixedModel& m) {
            return nlohmann::json{{"model", m.label}, {"h0_w_m2k", m.h0_w_m2k}, {"b_w_m2k", m.b_w_m2k},
                                  {"gamma_k_m3_kg", m.gamma_k_m3_kg}, {"exponent", m.exponent},
                                  {"rmse_w_m2k", m.rmse_w_m2k}, {"rmse_pct", m.rmse_pct}};
        };
        if (*json) {
            nlohmann::json out;
            out["n_points"] = r.n_points;
            out["fits"] = nlohmann::json::array();
            for (const auto& f : r.fits) out["fits"].push_back(fit_json(f));
            out["eq7_gamma_146"] = nlohmann::json::array();
            for (const auto& f : r.eq7_gamma_146) out["eq7_gamma_146"].push_back(fit_json(f));
            out["gamma_combined_k_m3_kg"] = r.gamma_combined_k_m3_kg;
            out["gamma_u_combined_k_m3_kg"] = r.gamma_u_combined_k_m3_kg;
            out["gamma_u_within_k_m3_kg"] = r.gamma_u_within_k_m3_kg;
            out["gamma_u_between_k_m3_kg"] = r.gamma_u_between_k_m3_kg;
            out["gamma_min_k_m3_kg"] = r.gamma_min_k_m3_kg;
            out["gamma_max_k_m3_kg"] = r.gamma_max_k_m3_kg;
            out["gamma_theory_table_mean_k_m3_kg"] = r.gamma_theory_table_mean_k_m3_kg;
            out["gamma_theory_paper_k_m3_kg"] = r.gamma_theory_paper_k_m3_kg;
            out["gamma_density_neutral_table_mean_k_m3_kg"] = r.gamma_density_neutral_table_mean_k_m3_kg;
            out["z_vs_paper"] = r.z_vs_paper;
            out["eq8"] = fixed_json(r.eq8);
            out["eq_s8"] = fixed_json(r.eq_s8);
            std::printf("%s\n", out.dump(2).c_str());
            return;
        }
        fmt::print("gamma in N = dT + gamma dC fitted to the paper's CFD whole-body h, Tables S8-S10 ({} cases)\n\n",
                   r.n_points);
        fmt::print("{:<38} {:<27} {:>15} {:>15} {:>15} {:>15} {:>7} {:>6} {:>9}\n", "form", "weighting",
                   "gamma K m3/kg", "profile range", "h0 W/m2K", "B (a)", "RMSE", "RMSE%", "chi2/dof");
        const auto row = [](const rc::CfdFormFit& f, bool gamma_free) {
            const std::string gamma = gamma_free ? fmt::format("{:.1f} +- {:.1f}", f.gamma_k_m3_kg, f.gamma_se_k_m3_kg)
                                                 : fmt::format("{:.0f} (fixed)", f.gamma_k_m3_kg);
            const std::string profile = gamma_free ? fmt::format("{:.1f}..{:.1f}", f.gamma_profile_lo_k_m3_kg,
                                                                 f.gamma_profile_hi_k_m3_kg)
                                                   : "-";
            const std::string h0 = f.form == rc::CfdForm::eq7_quarter
                                       ? fmt::format("{:.3f} +- {:.3f}", f.h0_w_m2k, f.h0_se_w_m2k)
                                       : "0 (none)";
            fmt::print("{:<38} {:<27} {:>15} {:>15} {:>15} {:>15} {:>7.3f} {:>6.1f} {:>9.2f}{}\n", rc::to_string(f.form),
                       rc::to_string(f.weighting), gamma, profile, h0, fmt::format("{:.3f} +- {:.3f}", f.b_w_m2k, f.b_se_w_m2k),
                       f.rmse_w_m2k, f.rmse_pct, f.chi2_per_dof, f.at_bound ? "  [parameter at bound]" : "");
        };
        for (const auto& f : r.fits) row(f, true);
        fmt::print("\nEq. 7 with gamma fixed at 146 (h0, B free):\n");
        for (const auto& f : r.eq7_gamma_146) row(f, false);
        fmt::print("\nFixed correlations on the same table:\n");
        for (const auto* m : {&r.eq8, &r.eq_s8})
            fmt::print("  {:<40} RMSE {:.3f} W/m2K, {:.1f} %\n", m->label, m->rmse_w_m2k, m->rmse_pct);
        fmt::print("\nCombined gamma (mean of the {} fits): {:.1f} +- {:.1f} K m3/kg\n", r.fits.size(),
                   r.gamma_combined_k_m3_kg, r.gamma_u_combined_k_m3_kg);
        fmt::print("  u = sqrt(mean within-fit se^2 + sample variance between fits) = sqrt({:.1f}^2 + {:.1f}^2); "
                   "fits range {:.1f}..{:.1f}\n",
                   r.gamma_u_within_k_m3_kg, r.gamma_u_between_k_m3_kg, r.gamma_min_k_m3_kg, r.gamma_max_k_m3_kg);
        fmt::print("Theory beta_C alpha/(beta_T D): {:.1f} (mean over the table's film states), 146 in Eq. 8; "
                   "(combined - 146)/u = {:+.2f}\n",
                   r.gamma_theory_table_mean_k_m3_kg, r.z_vs_paper);
        fmt::print("beta_C/beta_T (N = 0 where the film is density-neutral, Eq. 2 B_net = 0): {:.1f} (table mean)\n",
                   r.gamma_density_neutral_table_mean_k_m3_kg);
    });
}

}  // namespace

void add_physics_commands(CLI::App& app) {
    auto* physics = app.add_subcommand("physics", "Correlations from the paper: psychrometrics, buoyancy, convection");
    physics->require_subcommand(1);
    physics->footer(std::string("Units: °C, %, m/s; heat fluxes ") + ph::heat_flux_sign + ". Every command takes --json.");
    add_psychro(*physics);
    add_buoyancy(*physics);
    add_h_c(*physics);
    add_stagnation(*physics);
    add_threshold(*physics);
    add_cfd_gamma(*physics);
}

}  // namespace manikind::cli
