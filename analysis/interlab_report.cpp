#include "analysis/interlab_report.hpp"

#include <cmath>
#include <limits>
#include <map>

#include <fmt/core.h>

namespace manikind::analysis {
namespace {

double condition_value(const CaseResult& c, const char* channel) {
    for (const auto& cond : c.conditions)
        if (cond.channel == channel) return cond.e.value;
    return kNaN;
}

bool same_setting(const std::optional<double>& a, const std::optional<double>& b) {
    if (!a || !b) return a.has_value() == b.has_value();
    return std::abs(*a - *b) < 1e-9;
}

nlohmann::json finite_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

}  // namespace

InterlabReport compare_labs(const std::string& campaign, const std::vector<LabCampaignResult>& labs) {
    InterlabReport report;
    report.campaign = campaign;
    std::map<int, InterlabCase> by_case;
    for (const auto& lab : labs) {
        report.labs.push_back(lab.lab_id);
        for (const auto& w : lab.result.warnings) report.warnings.push_back(fmt::format("{}: {}", lab.lab_id, w));
        for (const auto& c : lab.result.cases) {
            auto [it, first] = by_case.try_emplace(c.case_id);
            InterlabCase& ic = it->second;
            if (first) {
                ic.case_id = c.case_id;
                ic.skin_setpoint_c = c.skin_setpoint_c;
                ic.wettedness = c.wettedness;
            } else if (!same_setting(ic.skin_setpoint_c, c.skin_setpoint_c) || !same_setting(ic.wettedness, c.wettedness)) {
                ic.note = fmt::format("lab '{}' ran case {} with another skin setpoint or wettedness: not the same "
                                      "level, no precision estimate",
                                      lab.lab_id, c.case_id);
            }
            InterlabLabLine line;
            line.lab_id = lab.lab_id;
            line.n = c.n_replicates;
            line.q_w_m2 = c.whole_body.q.value;
            line.expanded_u_w_m2 = c.type_a_estimable ? c.whole_body.q.U : kNaN;
            line.air_temp_c = condition_value(c, "air_temp_c");
            line.air_rh_pct = condition_value(c, "air_rh_pct");
            for (const auto& t : c.trials)
                if (t.included && std::isfinite(t.whole_body_q_w_m2)) line.replicates_w_m2.push_back(t.whole_body_q_w_m2);
            line.mandel_h = line.mandel_k = kNaN;
            ic.labs.push_back(std::move(line));
        }
    }

    for (auto& [id, ic] : by_case) {
        if (ic.note.empty()) {
            std::vector<LabCell> cells;
            for (const auto& l : ic.labs)
                if (l.replicates_w_m2.size() >= 2) cells.push_back({l.lab_id, l.replicates_w_m2});
            if (cells.size() < 2) {
                ic.note = fmt::format("{} lab(s) with two or more usable replicates: ISO 5725-2 needs two", cells.size());
            } else {
                ic.precision = estimate_precision(cells);
                for (auto& l : ic.labs)
                    for (const auto& s : ic.precision->cells)
                        if (s.lab_id == l.lab_id) l.mandel_h = s.mandel_h, l.mandel_k = s.mandel_k;
            }
        }
        report.cases.push_back(std::move(ic));
    }
    return report;
}

nlohmann::json interlab_to_json(const InterlabReport& report) {
    nlohmann::json j;
    j["campaign"] = report.campaign;
    j["heat_flux_sign"] = kHeatFluxSign;
    j["labs"] = report.labs;
    j["cases"] = nlohmann::json::array();
    for (const auto& c : report.cases) {
        nlohmann::json jc{{"case", c.case_id},
                          {"skin_setpoint_c", c.skin_setpoint_c ? nlohmann::json(*c.skin_setpoint_c) : nlohmann::json(nullptr)},
                          {"wettedness", c.wettedness ? nlohmann::json(*c.wettedness) : nlohmann::json(nullptr)},
                          {"labs", nlohmann::json::array()}};
        for (const auto& l : c.labs)
            jc["labs"].push_back({{"lab", l.lab_id},
                                  {"n", l.n},
                                  {"q_w_m2", finite_or_null(l.q_w_m2)},
                                  {"expanded_u_w_m2", finite_or_null(l.expanded_u_w_m2)},
                                  {"air_temp_c", finite_or_null(l.air_temp_c)},
                                  {"air_rh_pct", finite_or_null(l.air_rh_pct)},
                                  {"replicates_w_m2", l.replicates_w_m2},
                                  {"mandel_h", finite_or_null(l.mandel_h)},
                                  {"mandel_k", finite_or_null(l.mandel_k)}});
        if (c.precision) {
            const auto& p = *c.precision;
            jc["precision"] = {{"labs", p.labs},
                               {"grand_mean_w_m2", p.grand_mean},
                               {"repeatability_sd_w_m2", p.repeatability_sd},
                               {"between_lab_sd_w_m2", p.between_lab_sd},
                               {"reproducibility_sd_w_m2", p.reproducibility_sd},
                               {"repeatability_limit_w_m2", p.repeatability_limit},
                               {"reproducibility_limit_w_m2", p.reproducibility_limit},
                               {"cochran_c", finite_or_null(p.cochran_c)},
                               {"cochran_outcome", p.cochran_outcome}};
        } else {
            jc["precision"] = nullptr;
        }
        jc["note"] = c.note;
        j["cases"].push_back(std::move(jc));
    }
    j["warnings"] = report.warnings;
    return j;
}

std::string interlab_to_text(const InterlabReport& report) {
    std::string out = fmt::format("Campaign '{}' across {} labs; whole-body heat flux Q_Exp-WB in W/m², {}\n",
                                  report.campaign, report.labs.size(), kHeatFluxSign);
    out += "ISO 5725-2: s_r repeatability, s_L between labs, s_R reproducibility (SDs); r, R = 2.8 s (95 % limits)\n";
    for (const auto& c : report.cases) {
        out += fmt::format("\ncase {}", c.case_id);
        if (c.skin_setpoint_c) out += fmt::format(", skin {:.1f} °C", *c.skin_setpoint_c);
        if (c.wettedness) out += *c.wettedness > 0 ? ", wet" : ", dry";
        out += "\n";
        out += fmt::format("  {:<16} {:>2} {:>9} {:>16} {:>8} {:>7} {:>7} {:>7}\n", "lab", "n", "Q W/m²", "95 % CI",
                           "air °C", "RH %", "h", "k");
        for (const auto& l : c.labs) {
            const std::string ci = std::isfinite(l.expanded_u_w_m2)
                                       ? fmt::format("[{:.2f}, {:.2f}]", l.q_w_m2 - l.expanded_u_w_m2, l.q_w_m2 + l.expanded_u_w_m2)
                                       : std::string("(n < 2)");
            const auto opt = [](double v) { return std::isfinite(v) ? fmt::format("{:.2f}", v) : std::string("-"); };
            out += fmt::format("  {:<16} {:>2} {:>9.2f} {:>16} {:>8} {:>7} {:>7} {:>7}\n", l.lab_id, l.n, l.q_w_m2, ci,
                               opt(l.air_temp_c), opt(l.air_rh_pct), opt(l.mandel_h), opt(l.mandel_k));
        }
        if (c.precision) {
            const auto& p = *c.precision;
            out += fmt::format("  m = {:.2f}  s_r = {:.2f}  s_L = {:.2f}  s_R = {:.2f}  r = {:.2f}  R = {:.2f} W/m²", p.grand_mean,
                               p.repeatability_sd, p.between_lab_sd, p.reproducibility_sd, p.repeatability_limit,
                               p.reproducibility_limit);
            if (std::isfinite(p.cochran_c))
                out += fmt::format("  Cochran C = {:.3f}{}", p.cochran_c,
                                   p.cochran_outcome.empty() ? "" : " (" + p.cochran_outcome + ")");
            out += "\n";
        }
        if (!c.note.empty()) out += "  " + c.note + "\n";
    }
    for (const auto& w : report.warnings) out += "warning: " + w + "\n";
    return out;
}

}  // namespace manikind::analysis
