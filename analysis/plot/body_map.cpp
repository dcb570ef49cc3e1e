#include "analysis/plot/body_map.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <fmt/core.h>

#include "analysis/plot/svg_figure.hpp"

namespace manikind::analysis::plot {

const std::map<std::string, ZoneShape>& andi_zone_shapes() {
    // The console's body map (web/console.js), 200 x 400 px a view; x runs from the figure's
    // left, so the manikin's left side is on the reader's right in the front view.
    static const std::map<std::string, ZoneShape> shapes = {
        {"face", {true, 82, 8, 36, 42}},            {"scalp", {false, 82, 8, 36, 42}},
        {"neck", {true, 90, 50, 20, 14}},           {"upper_chest", {true, 68, 64, 64, 46}},
        {"abdomen", {true, 70, 110, 60, 40}},       {"pelvis_front", {true, 70, 150, 60, 30}},
        {"crotch", {true, 92, 180, 16, 14}},        {"upper_back", {false, 68, 64, 64, 50}},
        {"lower_back", {false, 70, 114, 60, 40}},   {"buttock_l", {false, 70, 154, 30, 40}},
        {"buttock_r", {false, 100, 154, 30, 40}},   {"shoulder_l", {true, 132, 64, 20, 20}},
        {"shoulder_r", {true, 48, 64, 20, 20}},     {"upper_arm_front_l", {true, 134, 84, 18, 56}},
        {"upper_arm_front_r", {true, 48, 84, 18, 56}}, {"upper_arm_back_l", {false, 48, 70, 18, 70}},
        {"upper_arm_back_r", {false, 134, 70, 18, 70}}, {"forearm_front_l", {true, 137, 140, 16, 58}},
        {"forearm_front_r", {true, 47, 140, 16, 58}}, {"forearm_back_l", {false, 47, 140, 16, 58}},
        {"forearm_back_r", {false, 137, 140, 16, 58}}, {"hand_l", {true, 138, 198, 18, 30}},
        {"hand_r", {true, 44, 198, 18, 30}},        {"thigh_front_l", {true, 102, 194, 27, 96}},
        {"thigh_front_r", {true, 71, 194, 27, 96}}, {"thigh_back_l", {false, 71, 194, 27, 96}},
        {"thigh_back_r", {false, 102, 194, 27, 96}}, {"calf_front_l", {true, 104, 290, 23, 88}},
        {"calf_front_r", {true, 73, 290, 23, 88}},  {"calf_back_l", {false, 73, 290, 23, 88}},
        {"calf_back_r", {false, 104, 290, 23, 88}}, {"foot_top_l", {true, 102, 378, 30, 20}},
        {"foot_top_r", {true, 68, 378, 30, 20}},    {"foot_sole_l", {false, 68, 378, 30, 20}},
        {"foot_sole_r", {false, 102, 378, 30, 20}},
    };
    return shapes;
}

std::string diverging_colour(double value, double limit) {
    const double t = limit > 0.0 && std::isfinite(value) ? std::clamp(value / limit, -1.0, 1.0) : 0.0;
    // White at zero; towards #b2182b (warm: the recording above the twin) or #2166ac (below).
    const double r = t >= 0 ? 255 - t * (255 - 178) : 255 + t * (255 - 33);
    const double g = t >= 0 ? 255 - t * (255 - 24) : 255 + t * (255 - 102);
    const double b = t >= 0 ? 255 - t * (255 - 43) : 255 + t * (255 - 172);
    auto c = [](double v) { return static_cast<int>(std::lround(std::clamp(v, 0.0, 255.0))); };
    return fmt::format("#{:02x}{:02x}{:02x}", c(r), c(g), c(b));
}

std::string body_map_svg(const BodyMap& map) {
    constexpr double kView = 200.0, kPanel = 2 * kView + 20.0, kTop = 40.0, kBody = 400.0;
    const double bar_x = 20.0 + kPanel * static_cast<double>(map.panels.size());
    const double width = bar_x + 150.0;
    const double height = kTop + kBody + 60.0 + 16.0 * static_cast<double>(map.notes.size());
    std::ostringstream o;
    o << fmt::format(R"(<svg xmlns="http://www.w3.org/2000/svg" width="{0}" height="{1}" viewBox="0 0 {0} {1}" )"
                     R"(role="img" aria-label="{2}" font-family="sans-serif">)",
                     width, height, xml_escape(map.title));
    o << R"(<rect width="100%" height="100%" fill="#ffffff"/>)";
    o << fmt::format(R"(<text x="20" y="24" font-size="16" font-weight="bold">{}</text>)", xml_escape(map.title));
    for (std::size_t p = 0; p < map.panels.size(); ++p) {
        const auto& panel = map.panels[p];
        const double x0 = 20.0 + kPanel * static_cast<double>(p);
        o << fmt::format(R"(<text x="{}" y="{}" text-anchor="middle" font-size="12">front</text>)", x0 + kView / 2, kTop + kBody + 14);
        o << fmt::format(R"(<text x="{}" y="{}" text-anchor="middle" font-size="12">back</text>)", x0 + 1.5 * kView, kTop + kBody + 14);
        o << fmt::format(R"(<text x="{}" y="{}" text-anchor="middle" font-size="13">{}</text>)", x0 + kView, kTop + kBody + 34,
                         xml_escape(panel.caption));
        for (const auto& [name, s] : andi_zone_shapes()) {
            const auto v = panel.value_by_zone.find(name);
            const std::optional<double> value =
                v == panel.value_by_zone.end() || !std::isfinite(v->second) ? std::nullopt : std::optional<double>(v->second);
            const std::string fill = value ? map.colour(std::clamp(*value, map.scale_min, map.scale_max)) : "#dddddd";
            o << fmt::format(R"(<rect x="{}" y="{}" width="{}" height="{}" rx="{:.1f}" fill="{}" stroke="#555" stroke-width="0.6">)",
                             x0 + s.x + (s.front ? 0.0 : kView), kTop + s.y, s.w, s.h, std::min(s.w, s.h) / 3.0, fill);
            o << "<title>" << xml_escape(map.tooltip ? map.tooltip(name, value) : name) << "</title></rect>";
        }
    }
    // The colour bar, its ends and its unit.
    constexpr int kSteps = 40;
    for (int i = 0; i < kSteps; ++i) {
        const double v = map.scale_min + (map.scale_max - map.scale_min) * i / (kSteps - 1.0);
        o << fmt::format(R"(<rect x="{}" y="{:.1f}" width="16" height="9" fill="{}"/>)", bar_x, kTop + kBody - 9.0 * (i + 1), map.colour(v));
    }
    o << fmt::format(R"(<text x="{}" y="{}" font-size="11">{:g}</text>)", bar_x + 20, kTop + kBody - 1, map.scale_min);
    o << fmt::format(R"(<text x="{}" y="{}" font-size="11">{:g}</text>)", bar_x + 20, kTop + kBody - 9.0 * kSteps + 9, map.scale_max);
    if (map.scale_min < 0.0 && map.scale_max > 0.0)  // a diverging scale: mark its zero
        o << fmt::format(R"(<text x="{}" y="{:.1f}" font-size="11">0</text>)", bar_x + 20,
                         kTop + kBody - 9.0 * kSteps * (0.0 - map.scale_min) / (map.scale_max - map.scale_min) + 4);
    o << fmt::format(R"(<text x="{}" y="{}" font-size="11">{}</text>)", bar_x - 8, kTop + kBody - 9.0 * kSteps - 8, xml_escape(map.scale_label));
    for (std::size_t i = 0; i < map.notes.size(); ++i)
        o << fmt::format(R"(<text x="20" y="{}" font-size="11" fill="#444">{}</text>)", kTop + kBody + 58 + 16.0 * static_cast<double>(i),
                         xml_escape(map.notes[i]));
    o << "</svg>\n";
    return o.str();
}

}  // namespace manikind::analysis::plot
