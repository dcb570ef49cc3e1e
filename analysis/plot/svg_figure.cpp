#include "analysis/plot/svg_figure.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>

#include <fmt/core.h>

namespace manikind::analysis::plot {
namespace {

constexpr double font_px = 12.0;
constexpr double title_font_px = 15.0;
constexpr double panel_title_font_px = 13.0;
constexpr double legend_row_px = 17.0;
constexpr double legend_sample_px = 26.0;
constexpr double colour_bar_width_px = 14.0;

// Rough rendered width of `text` in Helvetica: ~0.58 em per character (UTF-8 lead bytes only).
double text_width_px(std::string_view text, double size_px = font_px) {
    double chars = 0.0;
    for (const char c : text)
        if ((static_cast<unsigned char>(c) & 0xC0) != 0x80) chars += 1.0;
    return chars * 0.58 * size_px;
}

double exponent10(double v) { return std::floor(std::log10(std::fabs(v)) + 1e-9); }

struct Range {
    double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity();
    void add(double v) {
        if (!std::isfinite(v)) return;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    bool empty() const { return lo > hi; }
};

double at(const std::vector<double>& v, std::size_t i) { return i < v.size() ? v[i] : 0.0; }

Ticks axis_ticks(const Axis& axis, Range data) {
    if (!axis.categories.empty()) {
        Ticks t;
        t.lo = -0.5;
        t.hi = static_cast<double>(axis.categories.size()) - 0.5;
        t.step = 1.0;
        for (std::size_t i = 0; i < axis.categories.size(); ++i) {
            t.values.push_back(static_cast<double>(i));
            t.labels.push_back(axis.categories[i]);
        }
        return t;
    }
    if (axis.lo && axis.hi) return nice_ticks(*axis.lo, *axis.hi, axis.target_intervals, true);
    if (axis.lo) data.add(*axis.lo);
    if (axis.hi) data.add(*axis.hi);
    if (data.empty()) data = {0.0, 1.0};
    return nice_ticks(data.lo, data.hi, axis.target_intervals, false);
}

struct Mapping {
    Rect plot;
    double x_lo, x_hi, y_lo, y_hi;
    double px(double x) const { return plot.x + (x - x_lo) / (x_hi - x_lo) * plot.w; }
    double py(double y) const { return plot.y + plot.h - (y - y_lo) / (y_hi - y_lo) * plot.h; }
};

DataFootprint footprint(const XYPanel& p, const Mapping& m) {
    DataFootprint d;
    for (const auto& s : p.series) {
        const std::size_t n = std::min(s.x.size(), s.y.size());
        for (std::size_t i = 0; i < n; ++i) {
            const double cx = m.px(s.x[i]), cy = m.py(s.y[i]);
            if (s.markers) {
                const double r = s.marker_radius_px + 1.0;
                d.boxes.push_back({cx - r, cy - r, 2.0 * r, 2.0 * r});
            }
            if (i < s.x_err.size() && s.x_err[i] > 0.0)
                d.segments.push_back({m.px(s.x[i] - s.x_err[i]), cy, m.px(s.x[i] + s.x_err[i]), cy});
            if (i < s.y_err.size() && s.y_err[i] > 0.0)
                d.segments.push_back({cx, m.py(s.y[i] - s.y_err[i]), cx, m.py(s.y[i] + s.y_err[i])});
            if (s.line && i + 1 < n) d.segments.push_back({cx, cy, m.px(s.x[i + 1]), m.py(s.y[i + 1])});
        }
    }
    if (p.identity_line) {
        const double lo = std::max(m.x_lo, m.y_lo), hi = std::min(m.x_hi, m.y_hi);
        d.segments.push_back({m.px(lo), m.py(lo), m.px(hi), m.py(hi)});
    }
    return d;
}

struct LegendEntry {
    std::string label, colour, dash;
    bool line = false, markers = false;
};

std::vector<LegendEntry> legend_entries(const XYPanel& p) {
    std::vector<LegendEntry> out;
    for (const auto& s : p.series)
        if (!s.label.empty()) out.push_back({s.label, s.colour, s.dash, s.line || !s.y_err.empty() || !s.x_err.empty(), s.markers});
    if (p.identity_line && !p.identity_label.empty()) out.push_back({p.identity_label, "#888888", "5 4", true, false});
    return out;
}

std::string num(double v) { return fmt::format("{:.1f}", v); }

std::string text_el(double x, double y, std::string_view text, std::string_view anchor, std::string_view extra = {}) {
    return fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"{}\"{}{}>{}</text>\n", num(x), num(y), anchor,
                       extra.empty() ? "" : " ", extra, xml_escape(text));
}

std::string vertical_label(double x, double y, std::string_view text) {
    return fmt::format("<text x=\"{0}\" y=\"{1}\" text-anchor=\"middle\" transform=\"rotate(-90 {0} {1})\">{2}</text>\n",
                       num(x), num(y), xml_escape(text));
}

std::string line_el(double ax, double ay, double bx, double by, std::string_view colour, double width,
                    std::string_view dash = {}, double opacity = 1.0) {
    std::string extra;
    if (!dash.empty()) extra += fmt::format(" stroke-dasharray=\"{}\"", dash);
    if (opacity < 1.0) extra += fmt::format(" stroke-opacity=\"{:.2f}\"", opacity);
    return fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" stroke-width=\"{:.1f}\"{}/>\n", num(ax),
                       num(ay), num(bx), num(by), colour, width, extra);
}

// Tick labels on the left of a plot, gridlines across it.
void y_axis(std::string& o, const Rect& plot, const Ticks& t, const auto& py, bool grid) {
    for (std::size_t i = 0; i < t.values.size(); ++i) {
        const double y = py(t.values[i]);
        if (grid) o += line_el(plot.x, y, plot.x + plot.w, y, t.values[i] == 0.0 ? "#bbbbbb" : "#ececec", 1.0);
        o += line_el(plot.x - 4, y, plot.x, y, "#333333", 1.0);
        o += text_el(plot.x - 7, y + 4, t.labels[i], "end");
    }
}

void x_axis(std::string& o, const Rect& plot, const Ticks& t, const auto& px, bool grid, bool rotated) {
    const double base = plot.y + plot.h;
    for (std::size_t i = 0; i < t.values.size(); ++i) {
        const double x = px(t.values[i]);
        if (grid && !rotated) o += line_el(x, plot.y, x, base, t.values[i] == 0.0 ? "#bbbbbb" : "#ececec", 1.0);
        o += line_el(x, base, x, base + 4, "#333333", 1.0);
        if (rotated)
            o += fmt::format("<text x=\"{0}\" y=\"{1}\" text-anchor=\"end\" transform=\"rotate(-60 {0} {1})\">{2}</text>\n",
                             num(x + 3), num(base + 10), xml_escape(t.labels[i]));
        else
            o += text_el(x, base + 17, t.labels[i], "middle");
    }
}

double max_label_width(const Ticks& t) {
    double w = 0.0;
    for (const auto& l : t.labels) w = std::max(w, text_width_px(l));
    return w;
}

struct HeatLayout {
    Rect plot, bar;
    Ticks x_ticks, y_ticks, scale_ticks;
    double x_lo, x_hi, y_lo, y_hi, dx, dy;
};

double spacing(const std::vector<double>& centres) {
    return centres.size() > 1 ? (centres.back() - centres.front()) / static_cast<double>(centres.size() - 1) : 1.0;
}

HeatLayout layout_heat(const HeatMapPanel& p) {
    HeatLayout l;
    l.dx = spacing(p.x_centres);
    l.dy = spacing(p.y_centres);
    l.x_lo = p.x_centres.empty() ? 0.0 : p.x_centres.front() - l.dx / 2;
    l.x_hi = p.x_centres.empty() ? 1.0 : p.x_centres.back() + l.dx / 2;
    l.y_lo = p.y_centres.empty() ? 0.0 : p.y_centres.front() - l.dy / 2;
    l.y_hi = p.y_centres.empty() ? 1.0 : p.y_centres.back() + l.dy / 2;
    l.x_ticks = nice_ticks(l.x_lo, l.x_hi, p.x.target_intervals, true);
    l.y_ticks = nice_ticks(l.y_lo, l.y_hi, p.y.target_intervals, true);
    if (p.scale_lo && p.scale_hi) {
        l.scale_ticks = nice_ticks(*p.scale_lo, *p.scale_hi, 5, true);
    } else {
        Range v;
        for (const double x : p.values) v.add(x);
        if (v.empty()) v = {0.0, 1.0};
        if (p.diverging) {
            // Symmetric about 0, so white means "no difference".
            const double a = std::max(std::fabs(v.lo), std::fabs(v.hi));
            l.scale_ticks = nice_ticks(-a, a, 4);
        } else {
            l.scale_ticks = nice_ticks(v.lo, v.hi, 5);
        }
    }
    const double top = p.box.y + (p.title.empty() ? 10.0 : 28.0);
    const double left = 22.0 + max_label_width(l.y_ticks) + 10.0;
    const double bar_space = 14.0 + colour_bar_width_px + 8.0 + max_label_width(l.scale_ticks) + 26.0;
    l.plot = {p.box.x + left, top, p.box.w - left - bar_space, p.box.y + p.box.h - top - 46.0};
    l.bar = {l.plot.x + l.plot.w + 14.0, l.plot.y, colour_bar_width_px, l.plot.h};
    return l;
}

std::string render_heat(const HeatMapPanel& p, std::size_t index) {
    const HeatLayout l = layout_heat(p);
    const Mapping m{l.plot, l.x_lo, l.x_hi, l.y_lo, l.y_hi};
    const double s_lo = l.scale_ticks.lo, s_hi = l.scale_ticks.hi;
    auto t_of = [&](double v) { return std::clamp((v - s_lo) / (s_hi - s_lo), 0.0, 1.0); };
    std::string o = "<g class=\"heat-map\">\n";
    if (!p.title.empty()) o += text_el(l.plot.x + l.plot.w / 2, p.box.y + 16, p.title, "middle", fmt::format("font-size=\"{}\"", panel_title_font_px));
    const std::size_t ny = p.y_centres.size();
    for (std::size_t ix = 0; ix < p.x_centres.size(); ++ix)
        for (std::size_t iy = 0; iy < ny; ++iy) {
            const std::size_t k = ix * ny + iy;
            if (k >= p.values.size() || !std::isfinite(p.values[k])) continue;
            const double x0 = m.px(p.x_centres[ix] - l.dx / 2), x1 = m.px(p.x_centres[ix] + l.dx / 2);
            const double y0 = m.py(p.y_centres[iy] + l.dy / 2), y1 = m.py(p.y_centres[iy] - l.dy / 2);
            // +0.5 px overlap hides hairline seams between cells.
            o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{:.2f}\" height=\"{:.2f}\" fill=\"{}\">", num(x0), num(y0),
                             x1 - x0 + 0.5, y1 - y0 + 0.5, scale_colour(t_of(p.values[k]), p.diverging));
            if (k < p.tooltips.size()) o += "<title>" + xml_escape(p.tooltips[k]) + "</title>";
            o += "</rect>\n";
        }
    o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#333333\"/>\n", num(l.plot.x),
                     num(l.plot.y), num(l.plot.w), num(l.plot.h));
    y_axis(o, l.plot, l.y_ticks, [&](double y) { return m.py(y); }, false);
    x_axis(o, l.plot, l.x_ticks, [&](double x) { return m.px(x); }, false, false);
    o += text_el(l.plot.x + l.plot.w / 2, l.plot.y + l.plot.h + 38, p.x.label, "middle");
    o += vertical_label(p.box.x + 14, l.plot.y + l.plot.h / 2, p.y.label);

    // The colour bar: the scale from bottom (low) to top (high), ticked, labelled with its unit.
    o += "<g class=\"colour-bar\">\n";
    // A vertical gradient: stop offsets run top (high) to bottom (low).
    constexpr int stops = 16;
    o += "<defs><linearGradient id=\"colour-scale-" + std::to_string(index) + "\" x1=\"0\" y1=\"0\" x2=\"0\" y2=\"1\">";
    for (int i = 0; i <= stops; ++i) {
        const double t = static_cast<double>(i) / stops;
        o += fmt::format("<stop offset=\"{:.4f}\" stop-color=\"{}\"/>", t, scale_colour(1.0 - t, p.diverging));
    }
    o += "</linearGradient></defs>\n";
    o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"url(#colour-scale-{})\" stroke=\"#333333\"/>\n",
                     num(l.bar.x), num(l.bar.y), num(l.bar.w), num(l.bar.h), index);
    double label_w = 0.0;
    for (std::size_t i = 0; i < l.scale_ticks.values.size(); ++i) {
        const double y = l.bar.y + l.bar.h * (1.0 - t_of(l.scale_ticks.values[i]));
        o += line_el(l.bar.x + l.bar.w, y, l.bar.x + l.bar.w + 4, y, "#333333", 1.0);
        o += text_el(l.bar.x + l.bar.w + 6, y + 4, l.scale_ticks.labels[i], "start");
        label_w = std::max(label_w, text_width_px(l.scale_ticks.labels[i]));
    }
    o += vertical_label(l.bar.x + l.bar.w + 6 + label_w + 14, l.bar.y + l.bar.h / 2, p.scale_label);
    o += "</g>\n</g>\n";
    return o;
}

std::string render_xy(const XYPanel& p, std::size_t index) {
    const XYLayout l = layout_xy(p);
    const Mapping m{l.plot, l.x_ticks.lo, l.x_ticks.hi, l.y_ticks.lo, l.y_ticks.hi};
    const bool categorical = !p.x.categories.empty();
    std::string o = "<g class=\"xy-panel\">\n";
    if (!p.title.empty()) o += text_el(l.plot.x + l.plot.w / 2, p.box.y + 16, p.title, "middle", fmt::format("font-size=\"{}\"", panel_title_font_px));
    o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"white\" stroke=\"none\"/>\n", num(l.plot.x),
                     num(l.plot.y), num(l.plot.w), num(l.plot.h));
    y_axis(o, l.plot, l.y_ticks, [&](double y) { return m.py(y); }, true);
    x_axis(o, l.plot, l.x_ticks, [&](double x) { return m.px(x); }, true, categorical);
    const double base = l.plot.y + l.plot.h;
    const double x_label_y = categorical ? p.box.y + p.box.h - 6 : base + 36;
    if (!p.x.label.empty()) o += text_el(l.plot.x + l.plot.w / 2, x_label_y, p.x.label, "middle");
    o += vertical_label(p.box.x + 14, l.plot.y + l.plot.h / 2, p.y.label);

    // Data drawn inside a clip path, so fixed limits crop lines instead of spilling out.
    const std::string clip = fmt::format("plot-area-{}", index);
    o += fmt::format("<clipPath id=\"{}\"><rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/></clipPath>\n<g clip-path=\"url(#{})\">\n",
                     clip, num(l.plot.x), num(l.plot.y), num(l.plot.w), num(l.plot.h), clip);
    for (const auto& r : p.reference_lines) {
        if (r.horizontal) o += line_el(l.plot.x, m.py(r.at), l.plot.x + l.plot.w, m.py(r.at), r.colour, 1.2, r.dash);
        else o += line_el(m.px(r.at), l.plot.y, m.px(r.at), base, r.colour, 1.2, r.dash);
    }
    if (p.identity_line) {
        const double lo = std::max(m.x_lo, m.y_lo), hi = std::min(m.x_hi, m.y_hi);
        o += line_el(m.px(lo), m.py(lo), m.px(hi), m.py(hi), "#888888", 1.2, "5 4");
    }
    for (const auto& s : p.series) {
        const std::size_t n = std::min(s.x.size(), s.y.size());
        // 95 % bars with short caps, under the markers.
        for (std::size_t i = 0; i < n; ++i) {
            const double cx = m.px(s.x[i]), cy = m.py(s.y[i]);
            if (at(s.x_err, i) > 0.0) {
                const double a = m.px(s.x[i] - s.x_err[i]), b = m.px(s.x[i] + s.x_err[i]);
                o += line_el(a, cy, b, cy, s.colour, 1.0, {}, 0.55 * s.opacity + 0.2);
                o += line_el(a, cy - 3, a, cy + 3, s.colour, 1.0, {}, 0.55 * s.opacity + 0.2);
                o += line_el(b, cy - 3, b, cy + 3, s.colour, 1.0, {}, 0.55 * s.opacity + 0.2);
            }
            if (at(s.y_err, i) > 0.0) {
                const double a = m.py(s.y[i] - s.y_err[i]), b = m.py(s.y[i] + s.y_err[i]);
                o += line_el(cx, a, cx, b, s.colour, 1.2, {}, s.opacity);
                o += line_el(cx - 4, a, cx + 4, a, s.colour, 1.2, {}, s.opacity);
                o += line_el(cx - 4, b, cx + 4, b, s.colour, 1.2, {}, s.opacity);
            }
        }
        if (s.line && n > 1) {
            std::string pts;
            for (std::size_t i = 0; i < n; ++i) pts += fmt::format("{},{} ", num(m.px(s.x[i])), num(m.py(s.y[i])));
            o += fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"{:.1f}\"{} points=\"{}\"/>\n", s.colour,
                             s.line_width_px, s.dash.empty() ? "" : fmt::format(" stroke-dasharray=\"{}\"", s.dash), pts);
        }
        if (s.markers)
            for (std::size_t i = 0; i < n; ++i) {
                o += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"{:.1f}\" fill=\"{}\"{}>", num(m.px(s.x[i])), num(m.py(s.y[i])),
                                 s.marker_radius_px, s.colour,
                                 s.opacity < 1.0 ? fmt::format(" fill-opacity=\"{:.2f}\"", s.opacity) : "");
                if (i < s.tooltips.size()) o += "<title>" + xml_escape(s.tooltips[i]) + "</title>";
                o += "</circle>\n";
            }
    }
    o += "</g>\n";
    o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#333333\"/>\n", num(l.plot.x),
                     num(l.plot.y), num(l.plot.w), num(l.plot.h));

    if (l.legend) {
        const Rect& g = *l.legend;
        o += fmt::format("<g class=\"legend\">\n<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"white\" "
                         "fill-opacity=\"0.9\" stroke=\"#bbbbbb\"/>\n",
                         num(g.x), num(g.y), num(g.w), num(g.h));
        double y = g.y + 6 + legend_row_px / 2;
        for (const auto& e : legend_entries(p)) {
            const double x0 = g.x + 6, x1 = x0 + legend_sample_px - 6;
            if (e.line) o += line_el(x0, y, x1, y, e.colour, 2.0, e.dash);
            if (e.markers) o += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"3.5\" fill=\"{}\"/>\n", num((x0 + x1) / 2), num(y), e.colour);
            o += text_el(g.x + 6 + legend_sample_px, y + 4, e.label, "start");
            y += legend_row_px;
        }
        o += "</g>\n";
    }
    o += "</g>\n";
    return o;
}

}  // namespace

Ticks nice_ticks(double data_lo, double data_hi, int target_intervals, bool fixed) {
    double lo = data_lo, hi = data_hi;
    if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0.0, hi = 1.0;
    if (lo > hi) std::swap(lo, hi);
    const int target = std::max(1, target_intervals);
    const double scale = std::max(std::fabs(lo), std::fabs(hi));
    if (hi - lo <= scale * 1e-12) {
        // Zero width: a scale of ±10 % around the value (±1 around 0).
        const double pad = scale > 0.0 ? 0.1 * scale : 1.0;
        lo -= pad;
        hi += pad;
    }
    const double raw = (hi - lo) / target;
    const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
    double step = 10.0 * magnitude;
    for (const double mantissa : {1.0, 2.0, 2.5, 5.0})
        if (mantissa * magnitude >= raw * (1.0 - 1e-9)) {
            step = mantissa * magnitude;
            break;
        }
    Ticks t;
    t.step = step;
    double first = 0.0, last = 0.0;
    if (fixed) {
        first = std::ceil(lo / step - 1e-9);
        last = std::floor(hi / step + 1e-9);
        t.lo = lo;
        t.hi = hi;
    } else {
        first = std::floor(lo / step + 1e-9);
        last = std::ceil(hi / step - 1e-9);
        t.lo = first * step;
        t.hi = last * step;
    }
    for (double k = first; k <= last; k += 1.0) {
        // k * step, not a running sum: no accumulated rounding; and no "-0".
        double v = k * step;
        if (k == 0.0) v = 0.0;
        t.values.push_back(v);
        t.labels.push_back(format_tick(v, step));
    }
    return t;
}

std::string format_tick(double value, double step) {
    if (!std::isfinite(value)) return "nan";
    step = std::fabs(step);
    if (!(step > 0.0) || !std::isfinite(step)) return fmt::format("{:g}", value);
    if (std::fabs(value) < step * 1e-6) value = 0.0;  // no "-0" and no 1e-17 from k * step
    const double step_exp = exponent10(step);
    const double step_mantissa = step / std::pow(10.0, step_exp);
    const int extra = std::fabs(step_mantissa - 2.5) < 1e-6 ? 1 : 0;  // 2.5 x 10^n needs one more digit
    if (step >= 1e6 || step < 1e-4) {
        if (value == 0.0) return "0";
        double e = exponent10(value);
        const int decimals = std::max(0, static_cast<int>(e - step_exp) + extra);
        double mantissa = value / std::pow(10.0, e);
        const double rounding = std::pow(10.0, decimals);
        mantissa = std::round(mantissa * rounding) / rounding;
        if (std::fabs(mantissa) >= 10.0) {
            mantissa /= 10.0;
            e += 1.0;
        }
        return fmt::format("{:.{}f}e{}", mantissa, decimals, static_cast<int>(e));
    }
    const int decimals = std::max(0, static_cast<int>(-step_exp) + extra);
    return fmt::format("{:.{}f}", value, decimals);
}

std::string xml_escape(std::string_view text) {
    std::string out;
    out.reserve(text.size());
    for (const char c : text) {
        switch (c) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            case '\'': out += "&apos;"; break;
            default: out += c;
        }
    }
    return out;
}

bool segment_hits(const Rect& r, double ax, double ay, double bx, double by) {
    // Liang-Barsky: the parameter interval of the segment inside the rectangle is non-empty.
    double t0 = 0.0, t1 = 1.0;
    const double dx = bx - ax, dy = by - ay;
    const std::array<double, 4> p{-dx, dx, -dy, dy};
    const std::array<double, 4> q{ax - r.x, r.x + r.w - ax, ay - r.y, r.y + r.h - ay};
    for (std::size_t i = 0; i < 4; ++i) {
        if (p[i] == 0.0) {
            if (q[i] < 0.0) return false;
            continue;
        }
        const double t = q[i] / p[i];
        if (p[i] < 0.0) t0 = std::max(t0, t);
        else t1 = std::min(t1, t);
        if (t0 > t1) return false;
    }
    return true;
}

bool DataFootprint::hits(const Rect& r) const {
    for (const auto& b : boxes)
        if (r.intersects(b)) return true;
    for (const auto& s : segments)
        if (segment_hits(r, s.ax, s.ay, s.bx, s.by)) return true;
    return false;
}

std::optional<Rect> free_legend_corner(const Rect& plot, double legend_w_px, double legend_h_px, const DataFootprint& data) {
    constexpr double inset = 6.0;
    if (legend_w_px + 2 * inset > plot.w || legend_h_px + 2 * inset > plot.h) return std::nullopt;
    const double left = plot.x + inset, right = plot.x + plot.w - inset - legend_w_px;
    const double top = plot.y + inset, bottom = plot.y + plot.h - inset - legend_h_px;
    for (const auto& [x, y] : std::array<std::pair<double, double>, 4>{{{right, top}, {left, top}, {right, bottom}, {left, bottom}}}) {
        const Rect candidate{x, y, legend_w_px, legend_h_px};
        // A margin around the box, so no marker or line touches its border.
        if (!data.hits({x - 3, y - 3, legend_w_px + 6, legend_h_px + 6})) return candidate;
    }
    return std::nullopt;
}

XYLayout layout_xy(const XYPanel& p) {
    XYLayout l;
    Range xr, yr;
    for (const auto& s : p.series) {
        const std::size_t n = std::min(s.x.size(), s.y.size());
        for (std::size_t i = 0; i < n; ++i) {
            xr.add(s.x[i] - at(s.x_err, i));
            xr.add(s.x[i] + at(s.x_err, i));
            yr.add(s.y[i] - at(s.y_err, i));
            yr.add(s.y[i] + at(s.y_err, i));
        }
    }
    for (const auto& r : p.reference_lines) (r.horizontal ? yr : xr).add(r.at);
    if (p.identity_line) {
        // A parity plot: one range for both axes, so the 1:1 line is the diagonal.
        xr.add(yr.lo);
        xr.add(yr.hi);
        yr = xr;
    }
    l.x_ticks = axis_ticks(p.x, xr);
    l.y_ticks = axis_ticks(p.y, yr);

    const bool categorical = !p.x.categories.empty();
    const double top = p.box.y + (p.title.empty() ? 10.0 : 26.0);
    const double left = std::max(p.min_left_margin_px, 22.0 + max_label_width(l.y_ticks) + 10.0);
    double bottom = 46.0;
    if (categorical) bottom = 14.0 + max_label_width(l.x_ticks) * 0.87 + 24.0;  // labels at -60°
    const double right = 14.0;
    l.plot = {p.box.x + left, top, p.box.w - left - right, p.box.y + p.box.h - top - bottom};

    const auto entries = legend_entries(p);
    auto mapping = [&] { return Mapping{l.plot, l.x_ticks.lo, l.x_ticks.hi, l.y_ticks.lo, l.y_ticks.hi}; };
    l.data = footprint(p, mapping());
    if (entries.empty()) return l;
    double text_w = 0.0;
    for (const auto& e : entries) text_w = std::max(text_w, text_width_px(e.label));
    const double legend_w = std::max(p.min_legend_width_px, 6 + legend_sample_px + text_w + 8), legend_h = 12 + legend_row_px * static_cast<double>(entries.size());
    if (!p.legend_outside) l.legend = free_legend_corner(l.plot, legend_w, legend_h, l.data);
    if (!l.legend) {
        // Every corner has data: narrow the plot and put the legend to its right.
        l.legend_outside = true;
        l.plot.w = std::max(40.0, l.plot.w - legend_w - 12.0);
        l.legend = Rect{l.plot.x + l.plot.w + 12.0, l.plot.y, legend_w, legend_h};
        l.data = footprint(p, mapping());
    }
    return l;
}

std::string scale_colour(double t, bool diverging) {
    t = std::clamp(std::isfinite(t) ? t : 0.5, 0.0, 1.0);
    struct Rgb {
        double r, g, b;
    };
    // Diverging: ColorBrewer RdBu ends through white; sequential: light yellow to dark blue.
    static constexpr std::array<Rgb, 3> div{{{33, 102, 172}, {247, 247, 247}, {178, 24, 43}}};
    static constexpr std::array<Rgb, 4> seq{{{255, 255, 204}, {161, 218, 180}, {65, 182, 196}, {37, 52, 148}}};
    auto blend = [t](const auto& stops) {
        const double pos = t * static_cast<double>(stops.size() - 1);
        const std::size_t i = std::min(stops.size() - 2, static_cast<std::size_t>(pos));
        const double f = pos - static_cast<double>(i);
        const auto& a = stops[i];
        const auto& b = stops[i + 1];
        auto mix = [f](double u, double v) { return static_cast<int>(std::lround(u + (v - u) * f)); };
        return fmt::format("#{:02x}{:02x}{:02x}", mix(a.r, b.r), mix(a.g, b.g), mix(a.b, b.b));
    };
    return diverging ? blend(div) : blend(seq);
}

std::string to_svg(const Figure& f) {
    std::string o = fmt::format(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" "
        "font-family=\"Helvetica, Arial, sans-serif\" font-size=\"{2}\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
        f.width_px, f.height_px, font_px);
    if (!f.title.empty()) o += text_el(f.width_px / 2, 24, f.title, "middle", fmt::format("font-size=\"{}\"", title_font_px));
    double note_y = 42.0;
    for (const auto& note : f.notes) {
        o += text_el(f.width_px / 2, note_y, note, "middle", "font-size=\"11\" fill=\"#555555\"");
        note_y += 14.0;
    }
    std::size_t index = 0;
    for (const auto& p : f.xy_panels) o += render_xy(p, index++);
    index = 0;
    for (const auto& h : f.heat_maps) o += render_heat(h, index++);
    o += "</svg>\n";
    return o;
}

void write_svg(const Figure& figure, const std::filesystem::path& path) {
    std::ofstream out(path, std::ios::binary);
    out << to_svg(figure);
    if (!out) throw std::runtime_error("cannot write " + path.string());
}

}  // namespace manikind::analysis::plot
