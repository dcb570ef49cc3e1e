// The clothing test report (`manikin clothing --report`): one page per ensemble a lab can send to
// a client. Plain HTML with inline SVG, printable (one ensemble per printed page), no scripts
// and nothing loaded from elsewhere.
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <vector>
#include <sstream>

#include <fmt/core.h>

#include "analysis/clothing.hpp"
#include "analysis/plot/body_map.hpp"
#include "analysis/plot/svg_figure.hpp"

namespace manikind::analysis::clothing {
namespace {

using plot::xml_escape;

// The body map's colour, light to dark over 0 .. max_clo.
std::string colour_for(double clo, double max_clo) {
    const double t = std::clamp(clo / max_clo, 0.0, 1.0);
    // From pale yellow (bare) to deep blue (heavily insulated).
    const int r = static_cast<int>(std::lround(255 - t * (255 - 8)));
    const int g = static_cast<int>(std::lround(247 - t * (247 - 48)));
    const int b = static_cast<int>(std::lround(188 + t * (107 - 188 + 60)));
    return fmt::format("#{:02x}{:02x}{:02x}", std::clamp(r, 0, 255), std::clamp(g, 0, 255), std::clamp(b, 0, 255));
}

// The scale's top follows the data (issue 63): the largest local value rounded up to half a clo,
// at least 1 clo, so a light shirt is not a uniform pale map and an 8-clo bag is not all dark.
double scale_max_clo(const std::map<std::string, double>& clo_by_region) {
    double top = 0.0;
    for (const auto& [region, clo] : clo_by_region) top = std::max(top, clo);
    return std::max(1.0, std::ceil(top * 2.0 - 1e-9) / 2.0);
}

std::string body_map_svg(const EnsembleResult& e, const ZoneMap& map) {
    std::map<std::string, double> clo_by_region;
    for (const auto& rv : e.regions)
        if (rv.insulation_total) clo_by_region[rv.region] = rv.insulation_total->value / kClo_m2k_w;
    plot::BodyMap body;
    body.title = "Local total insulation";
    body.scale_label = "It, clo";
    body.scale_min = 0.0;
    body.scale_max = scale_max_clo(clo_by_region);
    body.colour = [top = body.scale_max](double clo) { return colour_for(clo, top); };
    plot::BodyMapPanel panel;
    std::map<std::string, const Zone*> zone_by_name;
    for (const auto& z : map.zones) {
        zone_by_name[z.name] = &z;
        if (const auto v = clo_by_region.find(z.region); v != clo_by_region.end()) panel.value_by_zone[z.name] = v->second;
    }
    body.panels.push_back(std::move(panel));
    body.tooltip = [&zone_by_name](const std::string& name, std::optional<double> clo) {
        const auto z = zone_by_name.find(name);
        const std::string value = clo ? fmt::format("{:.2f} clo", *clo) : "no value";
        return z == zone_by_name.end() ? fmt::format("{}: {}", name, value)
                                       : fmt::format("{} {} ({}): {}", z->second->zone, name, z->second->region, value);
    };
    return plot::body_map_svg(body);
}
std::string row(const char* name, const std::optional<Value>& v, bool insulation) {
    if (!v) return "";
    const std::string si = fmt::format("{:.4f} ± {:.4f}", v->value, v->U95);
    const std::string alt = insulation ? fmt::format("{:.3f} ± {:.3f} clo", v->value / kClo_m2k_w, v->U95 / kClo_m2k_w)
                            : v->unit == "m2kPa/W" ? fmt::format("{:.1f} ± {:.1f} m²Pa/W", 1000 * v->value, 1000 * v->U95)
                                                   : "";
    const std::string unit = v->unit == "m2K/W" ? "m²K/W" : v->unit == "m2kPa/W" ? "m²kPa/W" : "";
    return fmt::format("<tr><td>{}</td><td class=num>{} {}</td><td class=num>{}</td><td class=num>{:.2f}</td><td class=num>{}</td></tr>\n",
                       name, si, unit, alt, v->k, std::isfinite(v->u_a) ? fmt::format("{:.2g}", v->u_a) : "—");
}

// The regions head to foot in plain words (issue 64: the table was alphabetical in code names).
std::vector<std::string> regions_head_to_foot(const ZoneMap& map) {
    std::vector<std::pair<double, std::string>> by_height;
    std::map<std::string, std::pair<double, double>> sum;  // region -> (area x height, area)
    for (const auto& z : map.zones) {
        auto& s = sum[z.region];
        s.first += z.area_m2 * z.centroid_height_m;
        s.second += z.area_m2;
    }
    for (const auto& [region, s] : sum) by_height.emplace_back(s.second > 0 ? -s.first / s.second : 0.0, region);
    std::sort(by_height.begin(), by_height.end());
    std::vector<std::string> out;
    for (const auto& [h, region] : by_height) out.push_back(region);
    return out;
}
std::string plain_region(std::string region) {
    std::string side;
    if (region.size() > 2 && (region.ends_with("_l") || region.ends_with("_r"))) {
        side = region.ends_with("_l") ? " (left)" : " (right)";
        region.resize(region.size() - 2);
    }
    std::replace(region.begin(), region.end(), '_', ' ');
    return region + side;
}
std::string or_not_given(const std::string& s) { return s.empty() ? "not given" : s; }

}  // namespace

std::string to_html(const Result& r, const ZoneMap& map, const Campaign* campaign, const ReportInfo& info) {
    std::ostringstream o;
    o << "<!doctype html><html lang=en><head><meta charset=utf-8><title>"
      << xml_escape("Clothing test report: " + r.campaign) << "</title><style>"
      << "body{font:14px/1.4 system-ui,sans-serif;margin:2em;color:#111}"
      << "section{page-break-after:always;max-width:980px}h1{font-size:20px}h2{font-size:17px;margin-top:1.6em}"
      << "table{border-collapse:collapse;margin:.5em 0}td,th{border-bottom:1px solid #ccc;padding:3px 8px;text-align:left}"
      << ".num{text-align:right;font-variant-numeric:tabular-nums}.pass{color:#070}.fail{color:#b00;font-weight:bold}"
      << ".cols{display:flex;gap:2em;flex-wrap:wrap}.small{color:#555;font-size:12px}"
      << "header{display:flex;justify-content:space-between;border-bottom:2px solid #333;margin-bottom:1em}"
      << "header img{max-height:60px}.id td{border:none;padding:1px 8px 1px 0}.sign{margin-top:2em}.sign td{border:none;padding-right:4em}"
      // Page x of y when printed (Chromium's print to PDF fills the margin box).
      << "@page{size:A4;margin:18mm 14mm 18mm 14mm;@bottom-right{content:'page ' counter(page) ' of ' counter(pages);font:10px system-ui}"
      << "@bottom-left{content:'" << xml_escape(info.report_number.empty() ? r.campaign : info.report_number)
      << "';font:10px system-ui}}"
      << "</style></head><body>\n";
    // The test dates: the first and last trial start of each ensemble (campaign.json started_utc).
    std::map<std::string, std::pair<std::string, std::string>> dates;
    if (campaign)
        for (const auto& t : campaign->trials) {
            if (t.info.ensemble.empty() || t.info.started_utc.size() < 10) continue;
            const std::string day = t.info.started_utc.substr(0, 10);
            auto& d = dates[t.info.ensemble];
            if (d.first.empty() || day < d.first) d.first = day;
            if (d.second.empty() || day > d.second) d.second = day;
        }
    const int pages = static_cast<int>(r.ensembles.size());
    int page = 0;
    for (const auto& e : r.ensembles) {
        ++page;
        o << "<section><header><div>";
        if (!info.logo_data_uri.empty()) o << "<img alt='logo' src='" << xml_escape(info.logo_data_uri) << "'><br>";
        o << "<b>" << xml_escape(or_not_given(info.lab_name)) << "</b><br><span class=small>" << xml_escape(info.lab_address)
          << "<br>" << xml_escape(info.accreditation) << "</span></div><div class=small style='text-align:right'>"
          << xml_escape(fmt::format("Report {}", or_not_given(info.report_number))) << "<br>"
          << xml_escape(fmt::format("issued {}", or_not_given(info.report_date))) << "<br>"
          << xml_escape(fmt::format("ensemble {} of {}", page, pages)) << "</div></header>\n";
        o << "<h1>" << xml_escape(fmt::format("Clothing test report: {}", e.id)) << "</h1>\n";
        const auto d = dates.find(e.id);
        const std::string tested = d == dates.end() ? "not recorded" : d->second.first == d->second.second ? d->second.first
                                                                                                           : d->second.first + " to " + d->second.second;
        o << "<table class=id>"
          << fmt::format("<tr><td>Customer</td><td>{}</td><td>Sample</td><td>{}</td></tr>", xml_escape(or_not_given(info.customer)),
                         xml_escape(e.id == "nude" ? std::string("the bare manikin (the reference for Ia and Rea)")
                                    : info.sample.empty() ? e.description : info.sample + " (" + e.description + ")"))
          << fmt::format("<tr><td>Tested</td><td>{}</td><td>Standards followed</td><td>{}; {}</td></tr>", xml_escape(tested),
                         xml_escape(info.insulation_standard.empty() ? "insulation: not given" : "insulation: " + info.insulation_standard),
                         xml_escape(info.evaporative_standard.empty() ? "evaporative: not given" : "evaporative: " + info.evaporative_standard))
          << fmt::format("<tr><td>Manikin</td><td>{}</td><td>Chamber</td><td>{}</td></tr>", xml_escape(or_not_given(info.manikin)),
                         xml_escape(or_not_given(info.chamber)))
          << "</table>\n";
        o << "<p>" << xml_escape(e.description) << "<br><span class=small>"
          << xml_escape(fmt::format("campaign {}{}", r.campaign, r.baseline.empty() ? "" : "; nude baseline from " + r.baseline))
          << "</span></p>\n<div class=cols><div>";
        auto conditions = [&](const char* what, const std::optional<Conditions>& c) {
            if (!c) return;
            o << fmt::format("<p><b>{}</b>: {} trial{} (re-dressed between replicates); air {:.1f} °C, {:.0f} % RH, "
                             "{:.2f} m/s; mean skin {:.1f} °C</p>\n",
                             what, c->trials, c->trials == 1 ? "" : "s", c->air_temp_c, c->air_rh_pct, c->air_speed_m_s,
                             c->mean_skin_temp_c);
        };
        // Every condition the standard sets, pass or out of range with the value (docs/clothing.md).
        auto checks = [&](const std::vector<Check>& cs) {
            if (cs.empty()) return;
            o << "<table><tr><th>condition</th><th>value</th><th>status</th><th>requirement</th></tr>\n";
            for (const auto& c : cs)
                o << fmt::format("<tr><td>{}</td><td class=num>{}</td><td class={}>{}</td><td>{}<br><span class=small>{}</span></td></tr>\n",
                                 xml_escape(c.quantity),
                                 std::isfinite(c.value) ? xml_escape(fmt::format("{:.2f} {}", c.value, c.unit)) : "not recorded",
                                 c.status == "pass" ? "pass" : c.status == "out of range" ? "fail" : "small",
                                 xml_escape(c.status), xml_escape(c.requirement), xml_escape(c.source));
            o << "</table>\n";
        };
        // The standard the campaign followed (or the report-info file for an older campaign), else
        // the methods the analysis fits, said as such: never one guessed.
        const std::string ins_std =
            info.insulation_standard.empty() ? "the method of ASTM F1291 and ISO 15831; the campaign names neither" : info.insulation_standard;
        const std::string evap_std = info.evaporative_standard.empty() ? "the method of ASTM F2370; the campaign names no edition" : info.evaporative_standard;
        conditions(("Insulation (" + ins_std + ")").c_str(), e.insulation_conditions);
        checks(e.insulation_checks);
        conditions(e.evaporative_method.empty() ? ("Evaporative resistance (" + evap_std + ")").c_str()
                                                : ("Evaporative resistance (" + evap_std + ", " + e.evaporative_method + ")").c_str(),
                   e.evaporative_conditions);
        checks(e.evaporative_checks);
        if (!e.evaporative_withheld_reason.empty())
            o << "<p class=fail>" << xml_escape("Ret withheld: " + e.evaporative_withheld_reason) << "</p>\n";
        if (!e.intrinsic_evaporative_withheld_reason.empty())
            o << "<p>" << xml_escape("Recl withheld: " + e.intrinsic_evaporative_withheld_reason) << "</p>\n";
        if (e.evaporative_dry_bias_bound && std::isfinite(*e.evaporative_dry_bias_bound))
            o << "<p>" << xml_escape(fmt::format("Dry heat left in Ret (isothermal within {:.1f} K, no insulation test of the ensemble): "
                                                 "up to {:.1f} % {}, not in U.", kIsothermalTolerance_k,
                                                 100.0 * std::abs(*e.evaporative_dry_bias_bound),
                                                 *e.evaporative_dry_bias_bound < 0.0 ? "low" : "high"))
              << "</p>\n";
        o << "<table><tr><th>quantity</th><th>value ± U95</th><th></th><th>k</th><th>u<sub>A</sub></th></tr>\n";
        o << row("total insulation I<sub>t</sub>, parallel", e.insulation_total_parallel, true);
        o << row("total insulation I<sub>t</sub>, serial", e.insulation_total_serial, true);
        o << row("effective insulation I<sub>cle</sub>", e.insulation_effective_parallel, true);
        o << row("intrinsic insulation I<sub>cl</sub>", e.insulation_intrinsic_parallel, true);
        o << row("total evaporative resistance R<sub>et</sub>, parallel", e.evaporative_total_parallel, false);
        o << row("total evaporative resistance R<sub>et</sub>, serial", e.evaporative_total_serial, false);
        o << row("intrinsic evaporative resistance R<sub>ecl</sub>", e.evaporative_intrinsic_parallel, false);
        o << row("permeability index i<sub>m</sub>", e.permeability_index, false);
        o << "</table>\n";
        if (e.id != "nude")
            o << "<p>" << xml_escape(std::isfinite(e.fcl) ? fmt::format("Clothing area factor fcl = {:.3f}: {}.", e.fcl, e.fcl_reason)
                                                          : fmt::format("Clothing area factor fcl: none ({}).", e.fcl_reason))
              << "</p>\n";
        auto criterion = [&](const char* what, const std::optional<double>& cv, const std::optional<bool>& pass, double limit,
                             std::size_t n) {
            if (!cv) return;
            o << fmt::format("<p>{}: {} replicates, coefficient of variation {:.1f} % (limit {:.0f} %): <span class={}>{}</span></p>\n",
                             what, n, 100 * *cv, 100 * limit, *pass ? "pass" : "fail", *pass ? "pass" : "FAIL");
        };
        criterion("Replicates, insulation", e.insulation_cv, e.insulation_cv_pass, r.options.cv_limit_insulation,
                  e.insulation_replicates.size());
        criterion("Replicates, evaporative resistance", e.evaporative_cv, e.evaporative_cv_pass, r.options.cv_limit_evaporative,
                  e.evaporative_replicates.size());
        // Each re-dressing's own value (issue 64: only --json had them).
        if (const auto reps = r.replicates.find(e.id); reps != r.replicates.end()) {
            auto list = [&](const char* key, double scale, const char* unit) {
                const auto k = reps->second.find(key);
                if (k == reps->second.end() || k->second.empty()) return std::string();
                std::string out;
                for (double v : k->second) out += (out.empty() ? "" : ", ") + fmt::format("{:.3f}", v * scale);
                return out + " " + unit;
            };
            const std::string it = list("It_par", 1.0 / kClo_m2k_w, "clo"), ret = list("Ret_par", 1000.0, "m²Pa/W");
            if (!it.empty() || !ret.empty())
                o << "<p>Replicate values (each a re-dressing): " << xml_escape(it.empty() ? "" : "I_t " + it)
                  << xml_escape(!it.empty() && !ret.empty() ? "; " : "") << xml_escape(ret.empty() ? "" : "R_et " + ret) << "</p>\n";
        }
        for (const auto& n : e.notes) o << "<p class=small>Note: " << xml_escape(n) << "</p>\n";
        // The lab notebook: the campaign's notes, and the notes on this ensemble's trials.
        if (campaign) {
            std::set<std::string> own;
            for (const auto& t : campaign->trials)
                if (t.info.ensemble == e.id) own.insert(t.info.id);
            for (const auto& n : campaign->notes)
                if (n.trial.empty() || own.count(n.trial))
                    o << "<p class=small>" << xml_escape(fmt::format("Notebook ({}{}, {}): {}", n.kind,
                                                                   n.trial.empty() ? "" : ", trial " + n.trial, n.author, n.text))
                      << "</p>\n";
        }
        o << "</div><div><h2>Local total insulation</h2>" << body_map_svg(e, map)
          << "<p class=small>Each zone coloured by its region's total insulation (parallel), from 0 clo to the scale's top beside "
             "the map (the largest value rounded up to half a clo, at least 1); grey: no value.</p></div></div>\n";
        o << "<h2>By region</h2><table><tr><th>region</th><th>I<sub>t</sub> ± U95 (clo)</th><th>I<sub>cle</sub> ± U95 (clo)</th>"
             "<th>R<sub>et</sub> ± U95 (m²Pa/W)</th></tr>\n";
        std::vector<const RegionValues*> ordered;
        for (const auto& region : regions_head_to_foot(map))
            for (const auto& rv : e.regions)
                if (rv.region == region) ordered.push_back(&rv);
        for (const auto* rvp : ordered) {
            const auto& rv = *rvp;
            auto clo = [](const std::optional<Value>& v) {
                return v ? fmt::format("{:.2f} ± {:.2f}", v->value / kClo_m2k_w, v->U95 / kClo_m2k_w) : std::string("—");
            };
            o << fmt::format("<tr><td>{}</td><td class=num>{}</td><td class=num>{}</td><td class=num>{}</td></tr>\n",
                             xml_escape(plain_region(rv.region)), clo(rv.insulation_total), clo(rv.insulation_effective),
                             rv.evaporative_total ? fmt::format("{:.1f} ± {:.1f}", 1000 * rv.evaporative_total->value,
                                                                1000 * rv.evaporative_total->U95)
                                                  : std::string("—"));
        }
        o << "</table>\n<p class=small>"
          << xml_escape(fmt::format("U95: {:.0f} % intervals, Type A from the re-dressed replicates (s/√n), Type B from the "
                                    "instruments' specifications by Monte Carlo with errors shared by every trial (GUM "
                                    "Supplement 1), k from Student's t on the Welch-Satterthwaite degrees of freedom. 1 clo = "
                                    "0.155 m²K/W; i_m = I_t / (16.5 K/kPa × R_et). Method: total insulation per ASTM F1291 / "
                                    "ISO 15831 (parallel and serial), effective and intrinsic per ISO 9920, evaporative "
                                    "resistance per ASTM F2370; computed by manikind's manikin clothing.",
                                    100 * r.options.confidence))
          << "</p>\n<table class=sign><tr><td>Tested by: " << xml_escape(or_not_given(info.operator_name))
          << "</td><td>Approved by: " << xml_escape(or_not_given(info.approver))
          << "</td><td>Signature: ____________________</td></tr></table></section>\n";
    }
    if (!r.warnings.empty()) {
        o << "<section><h2>Warnings</h2><ul>";
        for (const auto& w : r.warnings) o << "<li>" << xml_escape(w) << "</li>";
        o << "</ul></section>";
    }
    o << "</body></html>\n";
    return o.str();
}

}  // namespace manikind::analysis::clothing
