#include "daemon/campaign_plan.hpp"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <set>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "analysis/local_room.hpp"
#include "base/text.hpp"
#include "base/toml_input.hpp"
#include "base/user_error.hpp"
#include "sim/campaign/campaign_generator.hpp"
#include "analysis/zone_map.hpp"
#include "physics/twin/twin.hpp"

namespace manikind {

nlohmann::json campaign_definition_json(const CampaignPlan& plan) {
    nlohmann::json j = {{"name", plan.name}, {"replicates", plan.replicates}, {"trial_duration_s", plan.trial_duration_s}};
    // Only clothing campaigns carry ensembles: earlier campaigns' stored definitions stay equal.
    if (!plan.ensembles.empty()) j["ensembles"] = analysis::ensembles_json(plan.ensembles);
    if (!plan.standards.empty()) j["standards"] = plan.standards;
    return j;
}

nlohmann::json case_conditions_json(const PlannedCase& c) {
    nlohmann::json j = {{"id", c.id},           {"chamber_temp_c", c.chamber_temp_c}, {"chamber_rh_pct", c.chamber_rh_pct},
                        {"skin_setpoint_c", c.skin_setpoint_c}, {"wet", c.wet}, {"sweat_rate_g_m2_h", c.sweat_rate_g_m2_h}};
    if (!c.ensemble.empty()) j["ensemble"] = c.ensemble;
    if (!c.test.empty()) j["test"] = c.test;
    // Only a case that states its room carries it: earlier campaigns' stored conditions stay equal.
    if (const auto room = analysis::local_room_json(analysis::andi35_zone_map(), c.local); !room.empty()) j["local"] = room;
    // Only physiological cases carry these: earlier campaigns' stored conditions stay equal.
    if (c.heat_flux_w_m2) {
        j["control"] = "constant-heat-flux";
        j["heat_flux_w_m2"] = *c.heat_flux_w_m2;
        if (!c.heat_flux_by_region_w_m2.empty()) j["heat_flux_by_region_w_m2"] = c.heat_flux_by_region_w_m2;
    }
    if (c.comfort) {
        j["control"] = "comfort";
        j["comfort_a_c"] = c.comfort->a_c;
        j["comfort_b_c_m2_w"] = c.comfort->b_c_m2_w;
    }
    if (c.model) {
        j["control"] = "physiological";
        nlohmann::json phases = nlohmann::json::array();
        for (const auto& ph : c.model->phases)
            phases.push_back({{"after_s", ph.after_s}, {"chamber_temp_c", ph.chamber_temp_c}, {"chamber_rh_pct", ph.chamber_rh_pct}});
        j["model"] = {{"name", c.model->name}, {"metabolic_met", c.model->metabolic_met},
                      {"duration_s", c.model->duration_s}, {"phases", phases}};
    }
    return j;
}

std::vector<std::string> plan_differences(const CampaignPlan& plan, const nlohmann::json& definition,
                                          const std::vector<nlohmann::json>& case_conditions) {
    std::vector<std::string> out;
    const auto compare = [&](const std::string& where, const nlohmann::json& stored, const nlohmann::json& planned) {
        for (const auto& [key, value] : planned.items())
            if (!stored.contains(key)) out.push_back(fmt::format("{}{}: not stored, now {}", where, key, value.dump()));
            else if (stored.at(key) != value)
                out.push_back(fmt::format("{}{}: was {}, now {}", where, key, stored.at(key).dump(), value.dump()));
    };
    compare("", definition, campaign_definition_json(plan));
    if (case_conditions.size() != plan.cases.size())
        out.push_back(fmt::format("cases: {} stored, {} in the plan", case_conditions.size(), plan.cases.size()));
    for (std::size_t i = 0; i < std::min(case_conditions.size(), plan.cases.size()); ++i)
        compare(fmt::format("case {} (position {}): ", plan.cases[i].id, i + 1), case_conditions[i],
                case_conditions_json(plan.cases[i]));
    return out;
}

// Table S3's measured enclosure for these chamber setpoints (within 0.5 °C and 1 %), else the
// setpoints: what chamber settling waits for when the plan does not say.
EnclosureTarget enclosure_target(const PlannedCase& c) {
    EnclosureTarget t{c.chamber_temp_c, c.chamber_rh_pct};
    for (const auto& s3 : sim::table_s3_cases())
        if (std::abs(s3.chamber_temp_c - c.chamber_temp_c) <= 0.5 && std::abs(s3.chamber_rh_pct - c.chamber_rh_pct) <= 1.0) {
            t = {s3.air_temp_c, s3.air_rh_pct};
            break;
        }
    return {c.enclosure_temp_c.value_or(t.air_c), c.enclosure_rh_pct.value_or(t.rh_pct)};
}

CampaignPlan table_s3_plan(const std::string& name) {
    CampaignPlan p;
    p.name = name;
    for (const auto& c : sim::table_s3_cases()) {
        p.cases.push_back({c.case_id, c.chamber_temp_c, c.chamber_rh_pct, c.skin_setpoint_c, c.wettedness > 0.5,
                           c.wettedness > 0.5 ? 300.0 : 0.0, std::nullopt, std::nullopt, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});
    }
    return p;
}

std::string plan_text_problem(const CampaignPlan& plan) {
    // The lengths the campaign file allows (parse_campaign_plan): 120 for the name, 60 for an id.
    if (const auto why = label_problem(plan.name, 120, true); !why.empty())
        return fmt::format("\"name\" '{}': {}", printable(plan.name, 60), why);
    for (const auto& [id, e] : plan.ensembles) {
        if (const auto why = label_problem(id, 60, true); !why.empty())
            return fmt::format("ensemble id '{}': {}", printable(id, 60), why);
        if (e.description.empty()) continue;
        if (const auto why = label_problem(e.description, 500); !why.empty())
            return fmt::format("ensembles.{}.description: {}", id, why);
    }
    for (const auto& [test, standard] : plan.standards)
        if (const auto why = label_problem(standard, 80); !why.empty()) return fmt::format("standards.{}: {}", test, why);
    for (const auto& c : plan.cases)
        for (const auto* field : {&c.ensemble, &c.test})
            if (!field->empty())
                if (const auto why = label_problem(*field, 60, true); !why.empty())
                    return fmt::format("case {}: '{}': {}", c.id, printable(*field, 60), why);
    return {};
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diagonal = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diagonal = up;
        }
    }
    return row[b.size()];
}

namespace {

// A misspelt key would otherwise be silently replaced by its default (replicate = 1 would run 3
// replicates), so every key the parser does not read is an error, with the nearest known key.
void refuse_unknown_keys(const toml::table& table, std::initializer_list<std::string_view> known, const std::string& source,
                         const std::string& prefix) {
    for (const auto& [key, node] : table) {
        const std::string_view k = key.str();
        if (std::find(known.begin(), known.end(), k) != known.end()) continue;
        std::string_view nearest;
        std::size_t best = std::string_view::npos;
        for (const auto candidate : known)
            if (const auto d = edit_distance(k, candidate); d < best) best = d, nearest = candidate;
        // Close: at most 2 edits, and fewer than a third of the key (so "id" does not suggest "wet").
        const bool close = best <= 2 && best * 3 <= std::max(k.size(), nearest.size());
        throw UserError(fmt::format("{}: {}{}: unknown key{}", toml_input::where(source, key.source()), prefix, k,
                                    close ? fmt::format(" (did you mean '{}'?)", nearest) : std::string()));
    }
}

// control = "physiological" and its [cases.model] table (docs/daemon.md, "Physiological trials").
void parse_physiological(const toml::table& t, const toml::node& node, PlannedCase& c, const std::string& source) {
    auto where = [&](const toml::node& n) { return toml_input::where(source, n); };
    std::string control = "constant-skin";
    if (const auto* v = t.get("control")) {
        if (!v->is_string()) throw UserError(fmt::format("{}: cases.control: expected a string", where(*v)));
        control = v->as_string()->get();
        if (control != "constant-skin" && control != "physiological" && control != "constant-heat-flux" && control != "comfort")
            throw UserError(fmt::format("{}: cases.control: \"{}\" is not a control mode (\"constant-skin\", the default, "
                                        "\"constant-heat-flux\", \"comfort\" or \"physiological\")",
                                        where(*v), control));
    }
    // Comfort mode (issue 65): t_sk = a - b q per zone, the coefficients the case's or the defaults.
    const auto* comfort_a = t.get("comfort_a_c");
    const auto* comfort_b = t.get("comfort_b_c_m2_w");
    if (control != "comfort") {
        for (const auto* n : {comfort_a, comfort_b})
            if (n)
                throw UserError(fmt::format("{}: cases.{}: a comfort equation's coefficient is for control = \"comfort\"",
                                            where(*n), n == comfort_a ? "comfort_a_c" : "comfort_b_c_m2_w"));
    } else {
        if (const auto* v = t.get("skin_setpoint_c"))
            throw UserError(fmt::format("{}: cases.skin_setpoint_c: in comfort mode each zone's skin follows its own heat loss "
                                        "(t_sk = comfort_a_c - comfort_b_c_m2_w q; remove it)",
                                        where(*v)));
        ComfortEquation eq;
        auto coefficient = [&](const toml::node* n, const char* key, double fallback, double lo, double hi) {
            if (!n) return fallback;
            if (!n->is_number()) throw UserError(fmt::format("{}: cases.{}: expected a number", where(*n), key));
            const double v = n->is_integer() ? static_cast<double>(n->as_integer()->get()) : n->as_floating_point()->get();
            if (!(v >= lo && v <= hi)) throw UserError(fmt::format("{}: cases.{}: {} is outside {}..{}", where(*n), key, v, lo, hi));
            return v;
        };
        eq.a_c = coefficient(comfort_a, "comfort_a_c", eq.a_c, 30.0, 40.0);
        eq.b_c_m2_w = coefficient(comfort_b, "comfort_b_c_m2_w", eq.b_c_m2_w, 0.0, 0.2);
        c.comfort = eq;
    }
    // Constant heat flux (issue 65): each zone's heating fixed, its skin temperature measured.
    const auto* flux = t.get("heat_flux_w_m2");
    const auto* by_region = t.get("heat_flux_by_region_w_m2");
    if (control != "constant-heat-flux") {
        for (const auto* n : {flux, by_region})
            if (n)
                throw UserError(fmt::format("{}: cases.{}: a heat flux setpoint is for control = \"constant-heat-flux\" (add it "
                                            "to the case)",
                                            where(*n), n == flux ? "heat_flux_w_m2" : "heat_flux_by_region_w_m2"));
    } else {
        if (!flux)
            throw UserError(fmt::format("{}: cases: control = \"constant-heat-flux\" needs heat_flux_w_m2 (every zone's "
                                        "heating, W/m²)",
                                        where(node)));
        if (const auto* v = t.get("skin_setpoint_c"))
            throw UserError(fmt::format("{}: cases.skin_setpoint_c: under constant heat flux the skin temperature is measured, "
                                        "not set (remove it)",
                                        where(*v)));
        auto flux_value = [&](const toml::node& n, const std::string& key) {
            if (!n.is_number()) throw UserError(fmt::format("{}: cases.{}: expected a number (W/m²)", where(n), key));
            const double v = n.is_integer() ? static_cast<double>(n.as_integer()->get()) : n.as_floating_point()->get();
            // Heat the zones give; the coolant loop's negative power is for constant skin only.
            if (!(v > 0.0 && v <= 1000.0))
                throw UserError(fmt::format("{}: cases.{}: {} W/m² is outside 0..1000 (the zones' heating; [safety] "
                                            "max_heater_power_w_m2 limits it further)",
                                            where(n), key, v));
            return v;
        };
        c.heat_flux_w_m2 = flux_value(*flux, "heat_flux_w_m2");
        if (by_region) {
            const auto* tab = by_region->as_table();
            if (!tab)
                throw UserError(fmt::format("{}: cases.heat_flux_by_region_w_m2: expected a table of region = W/m²", where(*by_region)));
            std::set<std::string> regions;
            for (const auto& z : analysis::andi35_zone_map().zones) regions.insert(z.region);
            for (const auto& [key, n] : *tab) {
                const std::string region(key.str());
                if (!regions.count(region)) {
                    std::string known;
                    for (const auto& r : regions) known += (known.empty() ? "" : ", ") + r;
                    throw UserError(fmt::format("{}: cases.heat_flux_by_region_w_m2.{}: no such region in the zone map ({})",
                                                where(n), region, known));
                }
                c.heat_flux_by_region_w_m2[region] = flux_value(n, "heat_flux_by_region_w_m2." + region);
            }
        }
    }
    const auto* model = t.get("model");
    if (control != "physiological") {
        if (model)
            throw UserError(fmt::format("{}: cases.model: a model is for control = \"physiological\" (add it to the case)",
                                        where(*model)));
        return;
    }
    if (!model || !model->is_table())
        throw UserError(fmt::format("{}: cases: control = \"physiological\" needs a [cases.model] table (name, "
                                    "metabolic_met, duration_min)",
                                    where(model ? *model : node)));
    // The model decides the skin and the sweat: a value here would be silently overridden.
    for (const char* key : {"skin_setpoint_c", "wet", "sweat_rate_g_m2_h", "ensemble", "test"})
        if (const auto* v = t.get(key))
            throw UserError(fmt::format("{}: cases.{}: a physiological case's skin temperature and sweating are the "
                                        "model's to decide (remove {})",
                                        where(*v), key, key));
    const auto& m = *model->as_table();
    refuse_unknown_keys(m, {"name", "metabolic_met", "duration_min", "phases"}, source, "cases.model.");
    auto number = [&](const toml::table& tab, const char* key, double fallback, double lo, double hi, const char* prefix) {
        const auto* n = tab.get(key);
        if (!n) return fallback;
        if (!n->is_number()) throw UserError(fmt::format("{}: {}{}: expected a number", where(*n), prefix, key));
        const double v = n->is_integer() ? static_cast<double>(n->as_integer()->get()) : n->as_floating_point()->get();
        if (!(v >= lo && v <= hi))
            throw UserError(fmt::format("{}: {}{}: {} is outside {}..{}", where(*n), prefix, key, v, lo, hi));
        return v;
    };
    PhysiologicalModel pm;
    if (const auto* n = m.get("name")) {
        if (!n->is_string() || n->as_string()->get() != "stolwijk-2026")
            throw UserError(fmt::format("{}: cases.model.name: the model manikind runs is \"stolwijk-2026\" (the paper's "
                                        "Stolwijk model, docs/thermoregulation.md)",
                                        where(*n)));
    }
    pm.metabolic_met = number(m, "metabolic_met", 1.5, 0.8, 4.0, "cases.model.");
    pm.duration_s = 60.0 * number(m, "duration_min", 120, 5, 24 * 60, "cases.model.");
    if (const auto* ph = m.get("phases")) {
        const auto* arr = ph->as_array();
        if (!arr) throw UserError(fmt::format("{}: cases.model.phases: expected [[cases.model.phases]] tables", where(*ph)));
        for (const auto& item : *arr) {
            const auto* pt = item.as_table();
            if (!pt) throw UserError(fmt::format("{}: cases.model.phases: expected tables", where(item)));
            refuse_unknown_keys(*pt, {"after_min", "chamber_temp_c", "chamber_rh_pct"}, source, "cases.model.phases.");
            if (!pt->get("after_min") || !pt->get("chamber_temp_c") || !pt->get("chamber_rh_pct"))
                throw UserError(fmt::format("{}: cases.model.phases: after_min, chamber_temp_c and chamber_rh_pct are required",
                                            where(item)));
            ChamberPhase phase;
            phase.after_s = 60.0 * number(*pt, "after_min", 0, 0, pm.duration_s / 60.0, "cases.model.phases.");
            phase.chamber_temp_c = number(*pt, "chamber_temp_c", 0, -40, 80, "cases.model.phases.");
            phase.chamber_rh_pct = number(*pt, "chamber_rh_pct", 0, 0, 100, "cases.model.phases.");
            if (!pm.phases.empty() && phase.after_s <= pm.phases.back().after_s)
                throw UserError(fmt::format("{}: cases.model.phases.after_min: phases must come in time order", where(item)));
            pm.phases.push_back(phase);
        }
    }
    c.model = pm;
    c.wet = false;  // the sweat is the model's, zone by zone; "wet" is the constant-skin flood
    c.sweat_rate_g_m2_h = 0.0;
}

}  // namespace

// [[cases.local]]: the room this case's trials meet where it is not uniform (issue 65; the same
// keys as [[simulation.local]]): the daemon's simulated world is that room for the case's trials,
// and the case's conditions, the export and reconcile's twin carry it. Entries add up where they
// meet; the last air speed named for a zone holds.
static void parse_case_room(const toml::table& t, PlannedCase& c, const std::string& source) {
    const auto* node = t.get("local");
    if (!node) return;
    const auto* arr = node->as_array();
    if (!arr || !arr->is_array_of_tables())
        throw UserError(fmt::format("{}: cases.local: expected [[cases.local]] tables (zones = [...], air_offset_c, "
                                    "radiant_offset_c, air_speed_m_s, contact_w_m2, solar_w_m2)", toml_input::where(source, *node)));
    const auto& map = analysis::andi35_zone_map();
    c.local.assign(map.size(), {});
    for (std::size_t i = 0; i < arr->size(); ++i) {
        const toml::table& e = *(*arr)[i].as_table();
        const std::string at = toml_input::where(source, e);
        refuse_unknown_keys(e, {"zones", "what", "air_offset_c", "radiant_offset_c", "air_speed_m_s", "contact_w_m2", "solar_w_m2"},
                            source, "cases.local.");
        const auto* zones = e.get("zones");
        if (!zones || !zones->is_array() || zones->as_array()->empty())
            throw UserError(fmt::format("{}: cases.local.zones: expected the zones, regions or segments it applies to "
                                        "(e.g. zones = [\"face\", \"hand_l\"])", at));
        if (const auto* w = e.get("what"); w && !w->is_string())
            throw UserError(fmt::format("{}: cases.local.what: expected text (what this is: \"a vent jet\")", at));
        auto value = [&](const char* key) -> std::optional<double> {
            const auto& range = analysis::local_range(key);
            const double lo = range.lo, hi = range.hi;
            const char* unit = range.unit;
            const auto* n = e.get(key);
            if (!n) return std::nullopt;
            if (!n->is_number()) throw UserError(fmt::format("{}: cases.local.{}: expected a number ({})", toml_input::where(source, *n), key, unit));
            const double v = n->is_integer() ? static_cast<double>(n->as_integer()->get()) : n->as_floating_point()->get();
            if (!(v >= lo && v <= hi))
                throw UserError(fmt::format("{}: cases.local.{}: {} {} is outside {}..{}", toml_input::where(source, *n), key, v, unit, lo, hi));
            return v;
        };
        const auto air = value("air_offset_c"), radiant = value("radiant_offset_c"), speed = value("air_speed_m_s"),
                   contact = value("contact_w_m2"), solar = value("solar_w_m2");
        for (const auto& z : *zones->as_array()) {
            if (!z.is_string()) throw UserError(fmt::format("{}: cases.local.zones: expected names (text)", toml_input::where(source, z)));
            const std::string name = z.as_string()->get();
            const auto named = map.zones_named(name);
            if (named.empty())
                throw UserError(fmt::format("{}: cases.local.zones: '{}' is no zone, region or segment of the zone map "
                                            "(a zone as face, hand_l; a region as chest, upper_arm_l; a segment as thigh)",
                                            toml_input::where(source, z), name));
            analysis::add_to_room(c.local, named, {air.value_or(0.0), radiant.value_or(0.0), speed, contact.value_or(0.0), solar.value_or(0.0)});
        }
    }
}

CampaignPlan parse_campaign_plan(const std::string& text, const std::string& source) {
    const toml::table root = toml_input::parse(text, source);
    auto where = [&](const toml::node& n) { return toml_input::where(source, n); };
    refuse_unknown_keys(root,
                        {"name", "replicates", "trial_duration_min", "settle_window_min", "settle_band_c", "settle_tolerance_c",
                         "settle_tolerance_rh_pct", "settle_timeout_min", "excursion_limit_min", "builtin_cases", "cases",
                         "ensembles", "standards"},
                        source, "");
    auto number = [&](const toml::table& t, const char* key, double fallback, double lo, double hi) {
        const auto* n = t.get(key);
        if (!n) return fallback;
        if (!n->is_number()) throw UserError(fmt::format("{}: {}: expected a number", where(*n), key));
        const double v = n->is_integer() ? static_cast<double>(n->as_integer()->get()) : n->as_floating_point()->get();
        if (!(v >= lo && v <= hi)) throw UserError(fmt::format("{}: {}: {} is outside {}..{}", where(*n), key, v, lo, hi));
        return v;
    };
    // Counts: 2.5 replicates is a typo, not 2.
    auto whole = [&](const toml::table& t, const char* key, double fallback, double lo, double hi) {
        const double v = number(t, key, fallback, lo, hi);
        if (v != std::floor(v))
            throw UserError(fmt::format("{}: {}: {} is not a whole number", where(*t.get(key)), key, v));
        return static_cast<int>(v);
    };
    CampaignPlan p;
    const auto* name = root.get("name");
    if (!name || !name->is_string()) throw UserError(fmt::format("{}: name: expected the campaign's name (a string)", source));
    p.name = name->as_string()->get();
    // The name becomes a folder name and a column in exports: printable, of a sane length, no
    // '/' (the same rule as every other way a plan arrives: plan_text_problem).
    if (const auto why = label_problem(p.name, 120, true); !why.empty())
        throw UserError(fmt::format("{}: name: {} (1 to 120 bytes of UTF-8 text, no control character, no '/')", where(*name), why));
    p.replicates = whole(root, "replicates", 3, 1, 20);
    p.trial_duration_s = 60.0 * number(root, "trial_duration_min", 75, 1, 24 * 60);
    p.settle_window_s = 60.0 * number(root, "settle_window_min", 10, 0, 600);
    p.settle_band_c = number(root, "settle_band_c", 0.3, 0.01, 10);
    p.settle_tolerance_c = number(root, "settle_tolerance_c", 0.5, 0.05, 10);
    p.settle_tolerance_rh_pct = number(root, "settle_tolerance_rh_pct", 5.0, 0.5, 50);
    p.settle_timeout_s = 60.0 * number(root, "settle_timeout_min", 180, 1, 24 * 60);
    p.excursion_limit_s = 60.0 * number(root, "excursion_limit_min", 2, 0.1, 120);
    if (const auto* b = root.get("builtin_cases")) {
        if (!b->is_string() || b->as_string()->get() != "table-s3")
            throw UserError(fmt::format("{}: builtin_cases: the only built-in list is \"table-s3\"", where(*b)));
        p.cases = table_s3_plan(p.name).cases;
    }
    if (const auto* cases = root.get("cases")) {
        const auto* arr = cases->as_array();
        if (!arr) throw UserError(fmt::format("{}: cases: expected [[cases]] tables", where(*cases)));
        for (const auto& node : *arr) {
            const auto* t = node.as_table();
            if (!t) throw UserError(fmt::format("{}: cases: expected [[cases]] tables", where(node)));
            refuse_unknown_keys(*t, {"id", "chamber_temp_c", "chamber_rh_pct", "skin_setpoint_c", "wet", "sweat_rate_g_m2_h",
                                     "heat_flux_w_m2", "heat_flux_by_region_w_m2", "comfort_a_c", "comfort_b_c_m2_w",
                                     "enclosure_temp_c", "enclosure_rh_pct", "ensemble", "test", "control", "model", "local"},
                                source, "cases.");
            PlannedCase c;
            c.id = whole(*t, "id", static_cast<double>(p.cases.size() + 1), 1, 1e6);
            // A case id names the case in results and exports, and pairs trials on continuing.
            for (const auto& earlier : p.cases)
                if (earlier.id == c.id)
                    throw UserError(fmt::format("{}: cases.id: {} is already the id of an earlier case (ids must differ)",
                                                where(t->get("id") ? *t->get("id") : node), c.id));
            if (!t->get("chamber_temp_c") || !t->get("chamber_rh_pct"))
                throw UserError(fmt::format("{}: cases: chamber_temp_c and chamber_rh_pct are required", where(node)));
            c.chamber_temp_c = number(*t, "chamber_temp_c", 0, -40, 80);
            c.chamber_rh_pct = number(*t, "chamber_rh_pct", 0, 0, 100);
            c.skin_setpoint_c = number(*t, "skin_setpoint_c", 35, 0, 60);
            if (const auto* w = t->get("wet")) {
                if (!w->is_boolean()) throw UserError(fmt::format("{}: wet: expected true or false", where(*w)));
                c.wet = w->as_boolean()->get();
            }
            c.sweat_rate_g_m2_h = number(*t, "sweat_rate_g_m2_h", c.wet ? 300 : 0, 0, 510);
            if (t->get("enclosure_temp_c")) c.enclosure_temp_c = number(*t, "enclosure_temp_c", 0, -40, 80);
            if (t->get("enclosure_rh_pct")) c.enclosure_rh_pct = number(*t, "enclosure_rh_pct", 0, 0, 100);
            if (!c.wet && c.sweat_rate_g_m2_h > 0)
                throw UserError(fmt::format("{}: cases.sweat_rate_g_m2_h: {} g/m²/h on a dry case (wet = false); set "
                                            "wet = true, or leave the rate out",
                                            where(*t->get("sweat_rate_g_m2_h")), c.sweat_rate_g_m2_h));
            // Clothing tests: the ensemble and the test go together; an evaporative test sweats,
            // an insulation test is dry (ASTM F2370, F1291).
            for (const char* key : {"ensemble", "test"})
                if (const auto* v = t->get(key); v && !v->is_string())
                    throw UserError(fmt::format("{}: cases.{}: expected a string", where(*v), key));
            if (const auto* v = t->get("ensemble")) c.ensemble = v->as_string()->get();
            if (const auto* v = t->get("test")) c.test = v->as_string()->get();
            if (!c.test.empty() && c.test != "insulation" && c.test != "evaporative")
                throw UserError(fmt::format("{}: cases.test: \"{}\" is not a test (\"insulation\" or \"evaporative\")",
                                            where(*t->get("test")), c.test));
            if (c.ensemble.empty() != c.test.empty())
                throw UserError(fmt::format("{}: cases: a clothing test names both ensemble and test (found only {})", where(node),
                                            c.ensemble.empty() ? "test" : "ensemble"));
            if (c.test == "evaporative" && !c.wet)
                throw UserError(fmt::format("{}: cases: an evaporative test needs the wet textile skin (wet = true)", where(node)));
            if (c.test == "insulation" && c.wet)
                throw UserError(fmt::format("{}: cases: an insulation test is dry (wet = false)", where(node)));
            parse_physiological(*t, node, c, source);
            parse_case_room(*t, c, source);
            p.cases.push_back(c);
        }
    }
    if (const auto* ens = root.get("ensembles")) {
        const auto* tab = ens->as_table();
        if (!tab) throw UserError(fmt::format("{}: ensembles: expected [ensembles.<id>] tables", where(*ens)));
        for (const auto& [key, node] : *tab) {
            const std::string id(key.str());
            const auto* e = node.as_table();
            if (!e) throw UserError(fmt::format("{}: ensembles.{}: expected a table with description and fcl", where(node), id));
            if (id == "nude" || id.empty() || id.size() > 60)
                throw UserError(fmt::format("{}: ensembles.{}: an ensemble id must be 1-60 characters and not \"nude\" (the "
                                            "bare manikin needs no entry)", where(node), id));
            refuse_unknown_keys(*e, {"description", "fcl", "fcl_u"}, source, "ensembles." + id + ".");
            analysis::Ensemble pe;
            if (const auto* d = e->get("description")) {
                if (!d->is_string()) throw UserError(fmt::format("{}: ensembles.{}.description: expected a string", where(*d), id));
                pe.description = d->as_string()->get();
            }
            if (e->get("fcl")) pe.fcl = number(*e, "fcl", 1.0, 1.0, 3.0);
            if (const auto* u = e->get("fcl_u")) {
                if (!pe.fcl)
                    throw UserError(fmt::format("{}: ensembles.{}.fcl_u: the uncertainty of a given fcl (give fcl too)", where(*u), id));
                pe.fcl_u = number(*e, "fcl_u", 0.0, 0.0, 1.0);
            }
            p.ensembles[id] = pe;
        }
    }
    // The standard each clothing test follows, with its edition: chosen here, printed on the report
    // (ASTM F1291 and ISO 15831 differ in the skin temperature, so the report must not guess).
    if (const auto* st = root.get("standards")) {
        const auto* tab = st->as_table();
        if (!tab)
            throw UserError(fmt::format("{}: standards: expected a table: [standards] insulation = \"ISO 15831:2004\", "
                                        "evaporative = \"ASTM F2370-16\"", where(*st)));
        refuse_unknown_keys(*tab, {"insulation", "evaporative"}, source, "standards.");
        for (const auto& [key, node] : *tab) {
            const std::string test(key.str());
            if (!node.is_string() || node.as_string()->get().empty())
                throw UserError(fmt::format("{}: standards.{}: expected the standard and its edition as text, e.g. \"{}\"", where(node),
                                            test, test == "insulation" ? "ASTM F1291-16" : "ASTM F2370-16"));
            const std::string standard = node.as_string()->get();
            if (const auto why = label_problem(standard, 80); !why.empty())
                throw UserError(fmt::format("{}: standards.{}: {} (1 to 80 bytes of text)", where(node), test, why));
            const bool runs = std::any_of(p.cases.begin(), p.cases.end(), [&](const PlannedCase& c) { return c.test == test; });
            if (!runs)
                throw UserError(fmt::format("{}: standards.{}: no case runs an {} test (a case with test = \"{}\")", where(node), test,
                                            test, test));
            p.standards[test] = standard;
        }
    }
    for (const auto& c : p.cases)
        if (!c.ensemble.empty() && c.ensemble != "nude" && !p.ensembles.count(c.ensemble))
            throw UserError(fmt::format("{}: case {}: ensemble \"{}\" is not defined (add [ensembles.{}], or \"nude\")", source,
                                        c.id, c.ensemble, c.ensemble));
    if (p.cases.empty()) throw UserError(fmt::format("{}: no cases (give [[cases]] or builtin_cases = \"table-s3\")", source));
    // The daemon's own rule for every name and text (LabDaemon::start_campaign applies it to
    // every plan): `campaign check` refuses what a start would.
    if (const auto why = plan_text_problem(p); !why.empty()) throw UserError(fmt::format("{}: {}", source, why));
    return p;
}

CampaignPlan load_campaign_plan(const std::string& file) {
    if (file == "builtin:table-s3") return table_s3_plan("table-s3");
    const auto text = toml_input::read_file(file);
    if (!text) throw UserError(fmt::format("{}: cannot open the campaign file", file));
    return parse_campaign_plan(*text, file);
}

std::string check_plan_against_limits(const CampaignPlan& plan, const config::SafetyLimits& l) {
    for (const auto& c : plan.cases) {
        if (c.chamber_temp_c < l.min_chamber_temp_c || c.chamber_temp_c > l.max_chamber_temp_c)
            return fmt::format("case {}: chamber_temp_c {} is outside the safety limits {}..{} °C (safety.min/max_chamber_temp_c)",
                               c.id, c.chamber_temp_c, l.min_chamber_temp_c, l.max_chamber_temp_c);
        if (c.chamber_rh_pct < l.min_chamber_rh_pct || c.chamber_rh_pct > l.max_chamber_rh_pct)
            return fmt::format("case {}: chamber_rh_pct {} is outside the safety limits {}..{} % (safety.min/max_chamber_rh_pct)",
                               c.id, c.chamber_rh_pct, l.min_chamber_rh_pct, l.max_chamber_rh_pct);
        if (c.model)
            for (const auto& ph : c.model->phases) {
                if (ph.chamber_temp_c < l.min_chamber_temp_c || ph.chamber_temp_c > l.max_chamber_temp_c)
                    return fmt::format("case {}: model phase after {:.0f} min: chamber_temp_c {} is outside the safety limits "
                                       "{}..{} °C (safety.min/max_chamber_temp_c)",
                                       c.id, ph.after_s / 60, ph.chamber_temp_c, l.min_chamber_temp_c, l.max_chamber_temp_c);
                if (ph.chamber_rh_pct < l.min_chamber_rh_pct || ph.chamber_rh_pct > l.max_chamber_rh_pct)
                    return fmt::format("case {}: model phase after {:.0f} min: chamber_rh_pct {} is outside the safety limits "
                                       "{}..{} % (safety.min/max_chamber_rh_pct)",
                                       c.id, ph.after_s / 60, ph.chamber_rh_pct, l.min_chamber_rh_pct, l.max_chamber_rh_pct);
            }
        if (c.heat_flux_w_m2) {
            // Constant heat flux: the heating is the setpoint; the skin's limits stop the trial
            // if it climbs past them (the recorder enforces max_skin_temp_c on every reading).
            double highest = *c.heat_flux_w_m2;
            for (const auto& [region, q] : c.heat_flux_by_region_w_m2) highest = std::max(highest, q);
            if (highest > l.max_heater_power_w_m2)
                return fmt::format("case {}: heat_flux_w_m2 {} is above the safety limit {} W/m² (safety.max_heater_power_w_m2)",
                                   c.id, highest, l.max_heater_power_w_m2);
            continue;
        }
        if (c.comfort) continue;  // the setpoints stay within [physiological] min/max_skin_setpoint_c, checked against [safety]
        if (!c.model && (c.skin_setpoint_c < l.min_skin_temp_c || c.skin_setpoint_c > l.max_skin_temp_c))
            return fmt::format("case {}: skin_setpoint_c {} is outside the safety limits {}..{} °C (safety.min/max_skin_temp_c)",
                               c.id, c.skin_setpoint_c, l.min_skin_temp_c, l.max_skin_temp_c);
    }
    return {};
}

std::string check_plan_against_devices(const CampaignPlan& plan, const config::Config& config) {
    const double rating = config.devices.manikin_max_heater_power_w_m2;
    const double limit = config.safety.max_heater_power_w_m2;
    for (const auto& c : plan.cases) {
        // Not for a physiological case: its skin is the model's, known only as the trial runs;
        // the loop's bounds, the heater limit and the follow check guard it then.
        if (c.model) continue;
        physics::twin::TrialConditions t;
        t.air_temp_c = c.chamber_temp_c;
        t.air_rh_pct = c.chamber_rh_pct;
        t.wettedness = c.wet ? 1.0 : 0.0;
        for (const auto& z : analysis::andi35_zone_map().zones)
            t.zones.push_back({z.zone, z.segment, z.region, z.area_m2, c.skin_setpoint_c});
        double worst_w_m2 = 0.0;
        int worst_zone = 0;
        for (const auto& f : physics::twin::predict(physics::twin::TwinVersion{}, t))
            if (f.q_total_w_m2 > worst_w_m2) worst_w_m2 = f.q_total_w_m2, worst_zone = f.zone;
        const std::string why = fmt::format("holding {} °C skin {} at {} °C, {} % RH needs about {:.0f} W/m² in zone {} "
                                            "(the baseline twin's steady loss in still air)",
                                            c.skin_setpoint_c, c.wet ? "wet" : "dry", c.chamber_temp_c, c.chamber_rh_pct,
                                            worst_w_m2, worst_zone);
        if (worst_w_m2 > rating)
            return fmt::format("case {}: {}, more than the heaters' rating of {} W/m² "
                               "(devices.manikin.max_heater_power_w_m2): that zone would never reach its setpoint",
                               c.id, why, rating);
        if (worst_w_m2 > limit)
            return fmt::format("case {}: {}, above safety.max_heater_power_w_m2 = {} W/m²: heating would stop "
                               "once the zone settled", c.id, why, limit);
    }
    return {};
}

}  // namespace manikind
