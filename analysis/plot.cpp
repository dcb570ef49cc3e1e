#include "analysis/plot.hpp"

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <spawn.h>
#include <sys/wait.h>
#include <fstream>

#include <fmt/core.h>

#include "analysis/input_error.hpp"
#include "physics/sign_convention.hpp"

namespace manikind::analysis {

namespace {

std::string xml_escape(const std::string& s) {
    std::string out;
    for (char c : s) {
        switch (c) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            default: out += c;
        }
    }
    return out;
}

// Tick step of 1, 2 or 5 x 10^n giving about `target` intervals.
double nice_step(double span, int target) {
    const double raw = span / target;
    const double mag = std::pow(10.0, std::floor(std::log10(raw)));
    for (double m : {1.0, 2.0, 5.0, 10.0})
        if (raw <= m * mag) return m * mag;
    return 10.0 * mag;
}

std::string label_of(const std::string& region) {
    std::string s = region;
    std::replace(s.begin(), s.end(), '_', ' ');
    if (s.size() > 2 && (s.ends_with(" l") || s.ends_with(" r"))) s = s.substr(0, s.size() - 2) + " (" + s.back() + ")";
    return s;
}

}  // namespace

std::string results_svg(const CampaignResult& r) {
    const int panel_w = 520, panel_h = 300, margin_l = 64, margin_r = 12, margin_t = 34, margin_b = 96;
    const int n = static_cast<int>(r.cases.size());
    const int cols = std::max(1, std::min(3, n));
    const int rows = std::max(1, (n + cols - 1) / cols);
    const int width = cols * panel_w, height = rows * panel_h + 40;

    // One y scale for every panel, so cases compare at a glance.
    double lo = 0.0, hi = 0.0;
    for (const auto& c : r.cases) {
        lo = std::min(lo, c.whole_body.q.value - c.whole_body.q.U);
        hi = std::max(hi, c.whole_body.q.value + c.whole_body.q.U);
        for (const auto& a : c.regions) {
            lo = std::min(lo, a.q.value - a.q.U);
            hi = std::max(hi, a.q.value + a.q.U);
        }
    }
    if (hi - lo < 1e-9) hi = lo + 1.0;
    const double step = nice_step(hi - lo, 6);
    lo = std::floor(lo / step) * step;
    hi = std::ceil(hi / step) * step;

    std::string svg = fmt::format(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" "
        "font-family=\"Helvetica, Arial, sans-serif\" font-size=\"11\">\n"
        "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
        "<text x=\"{2}\" y=\"22\" text-anchor=\"middle\" font-size=\"14\">{3}: heat flux Q (W/m², {5}), "
        "mean of replicates ± U ({4:.0f} %, Eq. S7)</text>\n",
        width, height, width / 2, xml_escape(r.campaign), r.options.confidence * 100.0, physics::heat_flux_sign);

    for (int i = 0; i < n; ++i) {
        const auto& c = r.cases[static_cast<std::size_t>(i)];
        const int ox = (i % cols) * panel_w, oy = 40 + (i / cols) * panel_h;
        const double x0 = ox + margin_l, x1 = ox + panel_w - margin_r;
        const double y0 = oy + margin_t, y1 = oy + panel_h - margin_b;
        auto y_of = [&](double q) { return y1 - (q - lo) / (hi - lo) * (y1 - y0); };
        std::string title = fmt::format("Case {} (n = {})", c.case_id, c.n_replicates);
        for (const auto& ce : c.conditions) {
            if (ce.channel == "air_temp_c") title += fmt::format(", T_air {:.1f} °C", ce.e.value);
            if (ce.channel == "air_rh_pct") title += fmt::format(", RH {:.1f} %", ce.e.value);
            if (ce.channel == "skin_temp_c") title += fmt::format(", T_sk {:.1f} °C", ce.e.value);
        }
        svg += fmt::format("<g>\n<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12\">{}</text>\n",
                           (x0 + x1) / 2, oy + 20, xml_escape(title));
        svg += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#444\"/>\n", x0, y0,
                           x1 - x0, y1 - y0);
        for (double t = lo; t <= hi + step * 1e-6; t += step) {
            const double y = y_of(t);
            svg += fmt::format("<line x1=\"{}\" y1=\"{:.1f}\" x2=\"{}\" y2=\"{:.1f}\" stroke=\"{}\"/>\n", x0, y, x1, y,
                               std::fabs(t) < step * 1e-6 ? "#888" : "#e4e4e4");
            svg += fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">{:g}</text>\n", x0 - 5, y + 4, t);
        }
        svg += fmt::format("<text transform=\"translate({},{}) rotate(-90)\" text-anchor=\"middle\">Q (W/m²)</text>\n",
                           ox + 16, (y0 + y1) / 2);
        std::vector<const AreaResult*> bars{&c.whole_body};
        for (const auto& a : c.regions) bars.push_back(&a);
        const double slot = (x1 - x0) / static_cast<double>(bars.size());
        svg += fmt::format("<line x1=\"{0:.1f}\" y1=\"{1}\" x2=\"{0:.1f}\" y2=\"{2}\" stroke=\"#bbb\" "
                           "stroke-dasharray=\"3,3\"/>\n", x0 + slot, y0, y1);
        for (std::size_t b = 0; b < bars.size(); ++b) {
            const auto& q = bars[b]->q;
            const double x = x0 + slot * (static_cast<double>(b) + 0.5);
            const char* colour = b == 0 ? "#b2182b" : "#2166ac";
            const double ya = y_of(q.value - q.U), yb = y_of(q.value + q.U);
            svg += fmt::format("<line x1=\"{0:.1f}\" y1=\"{1:.1f}\" x2=\"{0:.1f}\" y2=\"{2:.1f}\" stroke=\"{3}\"/>\n", x, ya,
                               yb, colour);
            for (double yc : {ya, yb})
                svg += fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"{}\"/>\n", x - 4,
                                   yc, x + 4, yc, colour);
            svg += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"{}\" fill=\"{}\"><title>{}: {:.2f} ± {:.2f} W/m² "
                               "(k = {:.3f})</title></circle>\n",
                               x, y_of(q.value), b == 0 ? 4.5 : 3.5, colour,
                               xml_escape(b == 0 ? "whole body" : label_of(bars[b]->name)), q.value, q.U, q.k);
            svg += fmt::format("<text transform=\"translate({:.1f},{}) rotate(-60)\" text-anchor=\"end\"{}>{}</text>\n",
                               x + 3, y1 + 10, b == 0 ? " font-weight=\"bold\"" : "",
                               xml_escape(b == 0 ? "whole body" : label_of(bars[b]->name)));
        }
        svg += "</g>\n";
    }
    svg += "</svg>\n";
    return svg;
}

std::string write_results_plot(const CampaignResult& result, const std::filesystem::path& svg_path,
                               const std::filesystem::path& png_path) {
    {
        std::ofstream out(svg_path, std::ios::binary);
        if (!out) throw InputError(svg_path.string(), 0, 0, "", "cannot write the plot");
        out << results_svg(result);
    }
    if (png_path.empty()) return fmt::format("plot written to {}", svg_path.string());
    // rsvg-convert (librsvg2-bin) renders SVG faithfully; without it the SVG is the figure.
    // Spawned without a shell, so no file name is ever interpreted.
    const std::string png = png_path.string(), svg = svg_path.string();
    std::vector<std::string> args{"rsvg-convert", "-f", "png", "-o", png, svg};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = 0;
    const int rc = posix_spawnp(&pid, "rsvg-convert", nullptr, nullptr, argv.data(), environ);
    if (rc != 0)
        return fmt::format("plot written to {}; no PNG: rsvg-convert is not installed (apt-get install librsvg2-bin)", svg);
    int status = 0;
    if (waitpid(pid, &status, 0) < 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0)
        return fmt::format("plot written to {}; rsvg-convert failed to write {}", svg, png);
    return fmt::format("plot written to {} and {}", svg_path.string(), png_path.string());
}

}  // namespace manikind::analysis
