#include "analysis/lab_report.hpp"

#include <cmath>
#include <map>

#include <fmt/core.h>

#include "analysis/plot.hpp"
#include "analysis/plot/svg_figure.hpp"

namespace manikind::analysis {
namespace {

using plot::xml_escape;

std::string num(double v, int decimals) { return std::isfinite(v) ? fmt::format("{:.{}f}", v, decimals) : "—"; }

std::string clock_of(std::int64_t utc_ns) { return utc_ns > 0 ? iso_utc_ms(utc_ns).substr(0, 19) + "Z" : "—"; }

std::string minutes_between(std::int64_t a_ns, std::int64_t b_ns) {
    return a_ns > 0 && b_ns >= a_ns ? fmt::format("{:.1f} min", static_cast<double>(b_ns - a_ns) / 60e9) : "—";
}

std::string events_table(const std::vector<ReportEvent>& events, const char* none) {
    if (events.empty()) return fmt::format("<p class=\"none\">{}</p>\n", none);
    std::string h = "<table><tr><th>time (UTC)</th><th>severity</th><th>kind</th><th>message</th></tr>\n";
    for (const auto& e : events)
        h += fmt::format("<tr class=\"{}\"><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n", xml_escape(e.severity), clock_of(e.utc_ns),
                         xml_escape(e.severity), xml_escape(e.kind), xml_escape(e.message));
    return h + "</table>\n";
}

std::string notes_list(const std::vector<const Note*>& notes, const char* none) {
    if (notes.empty()) return fmt::format("<p class=\"none\">{}</p>\n", none);
    std::string h = "<ul class=\"notes\">\n";
    for (const auto* n : notes)
        h += fmt::format("<li><b>{}</b> · {} · {}: {}</li>\n", clock_of(n->utc_ns), xml_escape(n->author), xml_escape(n->kind),
                         xml_escape(n->text));
    return h + "</ul>\n";
}

}  // namespace

std::string lab_report_html(const LabReportInput& in) {
    const Campaign& c = *in.campaign;
    const CampaignResult& r = *in.result;
    std::string h;
    const std::string title = in.only_trial.empty() ? fmt::format("Campaign report: {}", c.name)
                                                     : fmt::format("Trial report: {} of {}", in.only_trial, c.name);
    h += "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>" + xml_escape(title) + "</title>\n<style>\n"
         "body{font:11pt/1.35 system-ui,sans-serif;color:#111;margin:1.5cm}h1{font-size:16pt;margin:0}h2{font-size:13pt;"
         "margin:1.2em 0 .3em;border-bottom:1px solid #999}h3{font-size:11pt;margin:.8em 0 .2em}table{border-collapse:collapse;"
         "margin:.3em 0}th,td{border:1px solid #bbb;padding:2px 6px;text-align:left;font-variant-numeric:tabular-nums}"
         "th{background:#eee}.meta{color:#444}.none{color:#666;font-style:italic}.error td{color:#900;font-weight:600}"
         ".warn td{color:#850}.partial{color:#850;font-weight:600}section.trial{page-break-before:always}"
         "@media print{body{margin:0}a{color:#111}}svg{max-width:100%;height:auto}\n</style></head><body>\n";
    h += fmt::format("<h1>{}</h1>\n<p class=\"meta\">{} · generated {} · {} · heat flux: {}</p>\n", xml_escape(title), xml_escape(in.lab_name),
                     xml_escape(in.generated_utc), xml_escape(c.provenance.count("program") ? c.provenance.at("program") : ""),
                     xml_escape(std::string(kHeatFluxSign)));
    if (c.provenance.count("config_sha256"))
        h += fmt::format("<p class=\"meta\">configuration sha256 {}; twin {}</p>\n", xml_escape(c.provenance.at("config_sha256")),
                         xml_escape(c.provenance.count("twin_version") ? c.provenance.at("twin_version") : "baseline"));

    // The trials of the report, and which cases they belong to.
    std::map<std::string, const Trial*> by_id;
    for (const auto& t : c.trials) by_id[t.info.id] = &t;
    auto wanted = [&](const std::string& id) { return in.only_trial.empty() || id == in.only_trial; };

    // Conditions and results per case.
    h += "<h2>Conditions and whole-body heat flux</h2>\n<table><tr><th>case</th><th>chamber °C / % RH</th><th>skin setpoint °C</th>"
         "<th>skin</th><th>ensemble</th><th>measured air °C / % RH (mean)</th><th>Q<sub>WB</sub> W/m²</th><th>U<sub>95</sub> W/m²</th>"
         "<th>k</th><th>replicates used</th></tr>\n";
    for (const auto& cr : r.cases) {
        const TrialInfo* info = nullptr;
        bool any = false;
        for (const auto& t : cr.trials) {
            if (by_id.count(t.id)) info = &by_id[t.id]->info;
            any = any || wanted(t.id);
        }
        if (!any) continue;
        double air = NAN, rh = NAN;
        for (const auto& ce : cr.conditions) {
            if (ce.channel == "air_temp_c") air = ce.e.value;
            if (ce.channel == "air_rh_pct") rh = ce.e.value;
        }
        const auto& q = cr.whole_body.q;
        h += fmt::format("<tr><td>{}</td><td>{} / {}</td><td>{}</td><td>{}</td><td>{}</td><td>{} / {}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
                         cr.case_id, info && info->chamber_setpoint_temp_c ? num(*info->chamber_setpoint_temp_c, 1) : "—",
                         info && info->chamber_setpoint_rh_pct ? num(*info->chamber_setpoint_rh_pct, 1) : "—",
                         cr.skin_setpoint_c ? num(*cr.skin_setpoint_c, 2) : "model", cr.wettedness && *cr.wettedness > 0 ? "wet" : "dry",
                         info && !info->ensemble.empty() ? xml_escape(info->ensemble) : "—", num(air, 2), num(rh, 1), num(q.value, 2),
                         num(q.U, 2), num(q.k, 2), cr.n_replicates);
    }
    h += "</table>\n";
    for (const auto& cr : r.unanalysed_cases)
        h += fmt::format("<p class=\"partial\">case {}: no trial usable for results ({})</p>\n", cr.case_id,
                         cr.trials.empty() ? std::string("no trial") : xml_escape(cr.trials.front().exclusion_reason));
    if (in.only_trial.empty() && !r.cases.empty()) h += "<h3>Figure</h3>\n" + results_svg(r) + "\n";

    // The campaign's own notes and alarms.
    if (in.only_trial.empty()) {
        std::vector<const Note*> campaign_notes;
        for (const auto& n : c.notes)
            if (n.trial.empty()) campaign_notes.push_back(&n);
        h += "<h2>Lab notebook (the campaign)</h2>\n" + notes_list(campaign_notes, "no notes on the campaign");
        h += "<h2>Alarms outside the trials</h2>\n" + events_table(in.campaign_alarms, "none");
        if (!r.warnings.empty()) {
            h += "<h2>Warnings from the analysis</h2>\n<ul>\n";
            for (const auto& w : r.warnings) h += "<li>" + xml_escape(w) + "</li>\n";
            h += "</ul>\n";
        }
    }

    // One section per trial: stage times, the steady-state verdict, its window means, notes, alarms.
    std::map<std::string, const TrialResult*> results;
    for (const auto& cr : r.cases)
        for (const auto& t : cr.trials) results[t.id] = &t;
    for (const auto& cr : r.unanalysed_cases)
        for (const auto& t : cr.trials) results[t.id] = &t;
    for (const auto& rt : in.trials) {
        if (!wanted(rt.id)) continue;
        h += fmt::format("<section class=\"trial\"><h2>Trial {} (database id {}): {}{}</h2>\n", xml_escape(rt.id), rt.database_id,
                         xml_escape(rt.state), rt.reason.empty() ? "" : " (" + xml_escape(rt.reason) + ")");
        if (by_id.count(rt.id) && by_id[rt.id]->info.partial)
            h += "<p class=\"partial\">Still acquiring when this report was made: the data end at the last committed reading.</p>\n";
        h += "<h3>Stages</h3>\n<table><tr><th>stage</th><th>from (UTC)</th><th>lasted</th></tr>\n";
        for (std::size_t i = 0; i < rt.stages.size(); ++i) {
            const auto next = i + 1 < rt.stages.size() ? rt.stages[i + 1].utc_ns : 0;
            h += fmt::format("<tr><td>{}</td><td>{}</td><td>{}</td></tr>\n", xml_escape(rt.stages[i].message), clock_of(rt.stages[i].utc_ns),
                             next ? minutes_between(rt.stages[i].utc_ns, next) : "—");
        }
        h += "</table>\n";
        if (const auto it = results.find(rt.id); it != results.end()) {
            const TrialResult& tr = *it->second;
            const auto& s = tr.steady;
            h += fmt::format("<h3>Steady state: {}</h3>\n<p>{}worst zone {} varied {} °C over the window {}–{} min; used for the "
                             "case's results: {}{}</p>\n",
                             s.steady ? "steady" : "not steady", s.steady ? "" : xml_escape(s.reason) + "; ", s.worst_zone,
                             num(s.max_skin_fluctuation_c, 3), num(s.window_start_s / 60, 1), num(s.window_end_s / 60, 1),
                             tr.included ? "yes" : "no", tr.included ? "" : " (" + xml_escape(tr.exclusion_reason) + ")");
            h += fmt::format("<table><tr><th>whole-body Q W/m²</th><th>air °C</th><th>RH %</th><th>mean skin °C</th></tr>"
                             "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr></table>\n",
                             num(tr.whole_body_q_w_m2, 2), num(tr.air_temp_c, 2), num(tr.air_rh_pct, 1), num(tr.mean_skin_temp_c, 2));
        } else {
            h += "<p class=\"none\">not in the analysis (the trial did not finish acquiring)</p>\n";
        }
        std::vector<const Note*> notes;
        for (const auto& n : c.notes)
            if (n.trial == rt.id) notes.push_back(&n);
        h += "<h3>Lab notebook</h3>\n" + notes_list(notes, "no notes on this trial");
        h += "<h3>Alarms</h3>\n" + events_table(rt.alarms, "none") + "</section>\n";
    }
    h += "</body></html>\n";
    return h;
}

}  // namespace manikind::analysis
