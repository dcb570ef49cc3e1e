#include "analysis/plot.hpp"

#include <algorithm>
#include <cerrno>
#include <spawn.h>
#include <sys/wait.h>
#include <fstream>

#include <fmt/core.h>

#include "analysis/input_error.hpp"
#include "analysis/plot/svg_figure.hpp"
#include "physics/sign_convention.hpp"

namespace manikind::analysis {

namespace {

std::string label_of(const std::string& region) {
    std::string s = region;
    std::replace(s.begin(), s.end(), '_', ' ');
    if (s.size() > 2 && (s.ends_with(" l") || s.ends_with(" r"))) s = s.substr(0, s.size() - 2) + " (" + s.back() + ")";
    return s;
}

}  // namespace

std::string results_svg(const CampaignResult& r) {
    constexpr double panel_w_px = 520, panel_h_px = 340, header_px = 52;
    const int n = static_cast<int>(r.cases.size());
    const int cols = std::max(1, std::min(3, n));
    const int rows = std::max(1, (n + cols - 1) / cols);
    namespace pl = plot;
    pl::Figure fig;
    fig.width_px = std::max(640.0, cols * panel_w_px);
    fig.height_px = rows * panel_h_px + header_px;
    fig.title = r.campaign + ": heat flux Q by case (" + physics::heat_flux_sign + ")";
    const double coverage_pct = r.options.confidence * 100.0;
    fig.notes.push_back(fmt::format("positive = heat lost by the manikin; mean of replicates with bars ± U "
                                    "({:.0f} % coverage, Eq. S7)", coverage_pct));

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
    const pl::Ticks shared = pl::nice_ticks(lo, hi, 6);

    for (int i = 0; i < n; ++i) {
        const auto& c = r.cases[static_cast<std::size_t>(i)];
        pl::XYPanel p;
        const double centring_px = (fig.width_px - cols * panel_w_px) / 2;  // one narrow panel sits in the middle
        p.box = {centring_px + (i % cols) * panel_w_px, header_px + (i / cols) * panel_h_px, panel_w_px, panel_h_px};
        p.title = fmt::format("Case {} (n = {})", c.case_id, c.n_replicates);
        for (const auto& ce : c.conditions) {
            if (ce.channel == "air_temp_c") p.title += fmt::format(", T_air {:.1f} °C", ce.e.value);
            if (ce.channel == "air_rh_pct") p.title += fmt::format(", RH {:.1f} %", ce.e.value);
            if (ce.channel == "skin_temp_c") p.title += fmt::format(", T_sk {:.1f} °C", ce.e.value);
        }
        p.y.label = "Q (W/m²)";
        p.y.lo = shared.lo;
        p.y.hi = shared.hi;
        p.y.target_intervals = 6;
        p.reference_lines.push_back({true, 0.0, "#999999", ""});
        auto tooltip = [](const std::string& name, const Estimate& q) {
            return fmt::format("{}: {:.2f} ± {:.2f} W/m² (k = {:.3f})", name, q.value, q.U, q.k);
        };
        // The legend once, in the first panel: every panel uses the same two colours.
        pl::Series whole, regions;
        whole.label = i == 0 ? fmt::format("whole body, ± U ({:.0f} %)", coverage_pct) : "";
        whole.colour = "#b2182b";
        whole.marker_radius_px = 4.5;
        regions.label = i == 0 ? fmt::format("regions, ± U ({:.0f} %)", coverage_pct) : "";
        regions.colour = "#2166ac";
        p.x.categories.push_back("whole body");
        whole.x.push_back(0.0);
        whole.y.push_back(c.whole_body.q.value);
        whole.y_err.push_back(c.whole_body.q.U);
        whole.tooltips.push_back(tooltip("whole body", c.whole_body.q));
        for (const auto& a : c.regions) {
            regions.x.push_back(static_cast<double>(p.x.categories.size()));
            p.x.categories.push_back(label_of(a.name));
            regions.y.push_back(a.q.value);
            regions.y_err.push_back(a.q.U);
            regions.tooltips.push_back(tooltip(label_of(a.name), a.q));
        }
        p.series = {std::move(whole), std::move(regions)};
        fig.xy_panels.push_back(std::move(p));
    }
    return pl::to_svg(fig);
}

std::string write_results_plot(const CampaignResult& result, const std::filesystem::path& svg_path,
                               const std::filesystem::path& png_path) {
    {
        std::ofstream out(svg_path, std::ios::binary);
        out << results_svg(result);
        if (!out) throw InputError(svg_path.string(), 0, 0, "", "cannot write the plot");
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
