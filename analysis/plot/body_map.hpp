#pragma once
// The manikin drawn front and back, one rounded box per ANDI zone (the console's body map,
// web/console.js), coloured by a value per zone: the clothing report's local insulation and
// reconcile's standardised residual. Zones the drawing does not know are left out and counted.
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace manikind::analysis::plot {

// Where a zone is drawn in its view: front or back, x, y, width, height in the 200 x 400 px
// figure of one view (head at the top).
struct ZoneShape {
    bool front = true;
    double x = 0.0, y = 0.0, w = 0.0, h = 0.0;
};
// The shapes of the ANDI 35-zone map by zone name; other maps' zones are not drawn.
const std::map<std::string, ZoneShape>& andi_zone_shapes();

// One figure of the body: front and back side by side, a value per zone name.
struct BodyMapPanel {
    std::string caption;                       // under the pair, e.g. "before: baseline"
    std::map<std::string, double> value_by_zone;  // missing: drawn grey, "no value"
};
struct BodyMap {
    std::string title;                         // over the figure
    std::string scale_label;                   // beside the colour bar, with its unit
    double scale_min = 0.0, scale_max = 1.0;   // the colour bar's ends (values beyond are clamped)
    // Colour of a value within [scale_min, scale_max]; "#rrggbb".
    std::function<std::string(double)> colour;
    // A zone's tooltip: its number, name, region, and the value as the reader should see it.
    std::function<std::string(const std::string& zone_name, std::optional<double> value)> tooltip;
    std::vector<BodyMapPanel> panels;          // each a front + back pair, left to right
    std::vector<std::string> notes;            // under the figure
};

// Diverging scale for signed values around zero: blue (negative) - white - red (positive).
std::string diverging_colour(double value, double limit);

// The SVG document (standalone, no scripts, nothing loaded from elsewhere).
std::string body_map_svg(const BodyMap& map);

}  // namespace manikind::analysis::plot
