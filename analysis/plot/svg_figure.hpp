#pragma once
// The one plotting module behind every SVG the tool writes (analyze --plot, reconcile --plots,
// thermoreg --plot, thermoreg sweep): round axis ticks, axes whose labels carry units, line /
// marker / 95 % error-bar series, a legend placed clear of the data, heat maps with a colour
// bar, and XML-escaped text. Pure: builds strings; the only I/O is write_svg.
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace manikind::analysis::plot {

// ---- Ticks ----

// Round ticks: a step of 1, 2, 2.5 or 5 x 10^n giving at most about `target_intervals`
// intervals. `lo`/`hi` are the range the ticks cover (expanded outward to whole steps
// unless `fixed` asks for ticks inside [lo, hi] only). A zero-width or non-finite range is
// widened so the axis still has a scale.
struct Ticks {
    double lo = 0.0, hi = 1.0, step = 0.2;
    std::vector<double> values;
    std::vector<std::string> labels;  // `values` printed without float noise, e.g. "-120", "0.25"
};
Ticks nice_ticks(double data_lo, double data_hi, int target_intervals = 5, bool fixed = false);

// One tick value printed with the decimals its step needs (scientific for huge or tiny steps).
std::string format_tick(double value, double step);

// & < > " ' as entities, so any name or unit is safe in text and attributes.
std::string xml_escape(std::string_view text);

// ---- Geometry (pixels, y down) ----

struct Rect {
    double x = 0.0, y = 0.0, w = 0.0, h = 0.0;
    bool contains(double px, double py) const { return px >= x && px <= x + w && py >= y && py <= y + h; }
    bool intersects(const Rect& o) const { return x <= o.x + o.w && o.x <= x + w && y <= o.y + o.h && o.y <= y + h; }
};

// True when the segment (ax, ay)-(bx, by) passes through `r` (Liang-Barsky clipping).
bool segment_hits(const Rect& r, double ax, double ay, double bx, double by);

// What the data occupies in pixels: markers as small squares, lines and bars as segments.
struct DataFootprint {
    std::vector<Rect> boxes;
    struct Segment {
        double ax, ay, bx, by;
    };
    std::vector<Segment> segments;
    bool hits(const Rect& r) const;
};

// The legend box of size `legend_w_px` x `legend_h_px` in the first corner of `plot` (top
// right, top left, bottom right, bottom left) that no data touches; nullopt when all four do
// (the caller then puts the legend outside, to the right of the plot).
std::optional<Rect> free_legend_corner(const Rect& plot, double legend_w_px, double legend_h_px,
                                       const DataFootprint& data);

// ---- Figures ----

struct Axis {
    std::string label;                  // with its unit, e.g. "Measured Q (W/m²)"
    std::optional<double> lo, hi;       // fixed limits; otherwise from the data, rounded to ticks
    std::vector<std::string> categories;  // non-empty: x = 0, 1, ... labelled with these names
    int target_intervals = 5;
};

struct Series {
    std::string label;                    // legend text; empty = not in the legend
    std::string colour = "#1f77b4";
    std::vector<double> x, y;
    std::vector<double> x_err, y_err;     // 95 % half-widths (empty = none), drawn as capped bars
    bool line = false;                    // join the points
    bool markers = true;
    double line_width_px = 1.8;
    std::string dash;                     // SVG stroke-dasharray, e.g. "5 4"
    double marker_radius_px = 3.0;
    double opacity = 1.0;
    std::vector<std::string> tooltips;    // per point <title>, optional
};

// Horizontal or vertical reference line across the plot (e.g. Q = 0).
struct ReferenceLine {
    bool horizontal = true;
    double at = 0.0;
    std::string colour = "#888888";
    std::string dash;
};

struct XYPanel {
    Rect box;  // the whole panel in the figure, tick labels and axis labels included
    std::string title;
    Axis x, y;
    std::vector<Series> series;
    std::vector<ReferenceLine> reference_lines;
    bool identity_line = false;  // the 1:1 line of a parity plot (x and y share a range)
    std::string identity_label = "1:1";
    bool legend_outside = false;  // always right of the plot, e.g. so stacked panels share a time axis
    // Stacked panels set the same minimums so their plot areas line up.
    double min_left_margin_px = 0.0;
    double min_legend_width_px = 0.0;
};

// A grid of cells (regular in x and y) coloured by value, with a colour bar for its scale.
struct HeatMapPanel {
    Rect box;
    std::string title;
    Axis x, y;
    std::vector<double> x_centres, y_centres;  // cell centres, ascending, evenly spaced
    std::vector<double> values;                // values[ix * y_centres.size() + iy]; NaN = no cell
    std::vector<std::string> tooltips;         // optional, same layout as values
    std::string scale_label;                   // colour bar label with unit, e.g. "Core difference (°C)"
    bool diverging = true;  // blue - white - red around 0 (symmetric scale); else light to dark
    std::optional<double> scale_lo, scale_hi;  // otherwise from the values, rounded to ticks
};

struct Figure {
    double width_px = 640.0, height_px = 480.0;
    std::string title;
    std::vector<XYPanel> xy_panels;
    std::vector<HeatMapPanel> heat_maps;
    std::vector<std::string> notes;  // small print under the title, one line each
};

// Where an XY panel's parts land: the plot area, the legend (inside a free corner or to the
// right of a narrowed plot area) and the data in pixels, for tests and for rendering.
struct XYLayout {
    Rect plot;
    std::optional<Rect> legend;
    bool legend_outside = false;
    Ticks x_ticks, y_ticks;
    DataFootprint data;
};
XYLayout layout_xy(const XYPanel& panel);

// Colour of a value on a heat map's scale (`t` in 0..1), as "#rrggbb".
std::string scale_colour(double t, bool diverging);

std::string to_svg(const Figure& figure);

// Writes to_svg(figure); throws std::runtime_error naming the path when it cannot.
void write_svg(const Figure& figure, const std::filesystem::path& path);

}  // namespace manikind::analysis::plot
