// The plotting module behind every SVG (analysis/plot/svg_figure.hpp): round ticks, legend
// placement clear of the data, XML escaping, heat maps with a colour bar.
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "analysis/plot/body_map.hpp"
#include "analysis/plot/svg_figure.hpp"
#include "analysis/zone_map.hpp"

namespace pl = manikind::analysis::plot;

namespace {

// The step is 1, 2, 2.5 or 5 x 10^n.
bool round_step(double step) {
    const double mantissa = step / std::pow(10.0, std::floor(std::log10(step) + 1e-9));
    for (const double m : {1.0, 2.0, 2.5, 5.0})
        if (std::fabs(mantissa - m) < 1e-9) return true;
    return false;
}

// Every property a tick set must have for a data range [lo, hi].
void check_ticks(double lo, double hi, int target = 5) {
    INFO("range " << lo << " .. " << hi);
    const auto t = pl::nice_ticks(lo, hi, target);
    CHECK(round_step(t.step));
    REQUIRE(t.values.size() >= 2);
    CHECK(t.values.size() <= static_cast<std::size_t>(2 * target + 1));
    REQUIRE(t.labels.size() == t.values.size());
    CHECK(t.values.front() == Approx(t.lo));
    CHECK(t.values.back() == Approx(t.hi));
    CHECK(t.lo <= std::min(lo, hi));
    CHECK(t.hi >= std::max(lo, hi));
    std::set<std::string> distinct;
    for (std::size_t i = 0; i < t.values.size(); ++i) {
        INFO("tick " << t.labels[i]);
        // The label reads back as the tick, and is short: no float noise such as 0.30000000000000004.
        CHECK(std::stod(t.labels[i]) == Approx(t.values[i]).margin(t.step * 1e-6));
        CHECK(t.labels[i].size() <= 8);
        CHECK(t.labels[i] != "-0");
        // A whole number of steps from zero.
        CHECK(std::fabs(t.values[i] / t.step - std::round(t.values[i] / t.step)) < 1e-6);
        distinct.insert(t.labels[i]);
    }
    CHECK(distinct.size() == t.labels.size());
}

}  // namespace

TEST_CASE("plot ticks: -171 .. -5.94 gives round ticks covering it, never -88.6", "[analysis][plot]") {
    const auto t = pl::nice_ticks(-171.0, -5.94);
    CHECK(t.labels == std::vector<std::string>{"-200", "-150", "-100", "-50", "0"});
    check_ticks(-171.0, -5.94);
}

TEST_CASE("plot ticks: 0 .. 1 in steps of 0.2 printed without float noise", "[analysis][plot]") {
    const auto t = pl::nice_ticks(0.0, 1.0);
    CHECK(t.labels == std::vector<std::string>{"0.0", "0.2", "0.4", "0.6", "0.8", "1.0"});
    CHECK(pl::nice_ticks(0.1, 0.7, 6).labels == std::vector<std::string>{"0.1", "0.2", "0.3", "0.4", "0.5", "0.6", "0.7"});
    CHECK(pl::nice_ticks(0.0, 10.0, 4).labels == std::vector<std::string>{"0.0", "2.5", "5.0", "7.5", "10.0"});
    check_ticks(0.0, 1.0);
}

TEST_CASE("plot ticks: tiny, huge, negative, offset and reversed ranges", "[analysis][plot]") {
    check_ticks(1e-9, 3e-9);
    check_ticks(-2e-7, 5e-7);
    check_ticks(0.0, 3e9);
    check_ticks(-4.2e12, 1.1e12);
    check_ticks(1000.001, 1000.004);  // narrow span far from zero
    check_ticks(34.2, 39.87, 6);
    check_ticks(-412.5, 388.0, 8);
    check_ticks(5.0, -5.0);
    check_ticks(0.0, 120.0, 6);
    const auto huge = pl::nice_ticks(0.0, 3e9);
    CHECK(huge.labels == std::vector<std::string>{"0", "1e9", "2e9", "3e9"});
    CHECK(pl::nice_ticks(0.0, 1e7, 4).labels == std::vector<std::string>{"0", "2.5e6", "5.0e6", "7.5e6", "1.00e7"});
    const auto tiny = pl::nice_ticks(1e-9, 3e-9);
    CHECK(tiny.labels.front() == "1.0e-9");
}

TEST_CASE("plot ticks: a zero-width range still gets a scale around its value", "[analysis][plot]") {
    check_ticks(5.0, 5.0);
    check_ticks(0.0, 0.0);
    check_ticks(-3e-6, -3e-6);
    const auto t = pl::nice_ticks(0.0, 0.0);
    CHECK(t.lo < 0.0);
    CHECK(t.hi > 0.0);
    const auto nan = pl::nice_ticks(std::nan(""), 1.0);  // no data: a unit axis, not a crash
    CHECK(nan.values.size() >= 2);
}

TEST_CASE("plot ticks: fixed limits keep the range and tick only inside it", "[analysis][plot]") {
    const auto t = pl::nice_ticks(0.0, 117.0, 6, true);
    CHECK(t.lo == 0.0);
    CHECK(t.hi == 117.0);
    CHECK(t.labels == std::vector<std::string>{"0", "20", "40", "60", "80", "100"});
    const auto cells = pl::nice_ticks(29.5, 50.5, 5, true);  // heat-map cell edges
    CHECK(cells.labels == std::vector<std::string>{"30", "35", "40", "45", "50"});
}

TEST_CASE("plot: XML escaping of every text", "[analysis][plot]") {
    CHECK(pl::xml_escape("a & b < c > \"d\" 'e'") == "a &amp; b &lt; c &gt; &quot;d&quot; &apos;e&apos;");
    CHECK(pl::xml_escape("Q (W/m²)") == "Q (W/m²)");
    pl::Figure f;
    f.title = "Case <1> & \"2\"";
    f.notes.push_back("note <b>");
    pl::XYPanel p;
    p.box = {0, 40, 640, 440};
    p.title = "panel & co";
    p.x.label = "x <unit>";
    p.y.label = "y & z";
    pl::Series s;
    s.label = "twin <v2> & \"fit\"";
    s.x = {0.0, 1.0};
    s.y = {0.0, 1.0};
    s.tooltips = {"a < b", "c > d"};
    p.series.push_back(s);
    pl::HeatMapPanel h;
    h.box = {0, 480, 640, 400};
    h.x_centres = {1.0, 2.0};
    h.y_centres = {1.0};
    h.values = {0.5, -0.5};
    h.scale_label = "diff & <unit>";
    h.tooltips = {"<1>", "&2"};
    f.xy_panels.push_back(p);
    f.heat_maps.push_back(h);
    const std::string svg = pl::to_svg(f);
    for (const char* raw : {"<1>", "<b>", "<unit>", "<v2>", "& ", "a < b", "c > d", "\"2\"", "&2"}) {
        INFO(raw);
        CHECK(svg.find(raw) == std::string::npos);
    }
    CHECK(svg.find("Case &lt;1&gt; &amp; &quot;2&quot;") != std::string::npos);
    CHECK(svg.find("twin &lt;v2&gt; &amp; &quot;fit&quot;") != std::string::npos);
    CHECK(svg.find("diff &amp; &lt;unit&gt;") != std::string::npos);
}

TEST_CASE("plot: a segment hits a rectangle only where it passes through it", "[analysis][plot]") {
    const pl::Rect r{10, 10, 20, 20};
    CHECK(pl::segment_hits(r, 0, 0, 40, 40));     // through the diagonal
    CHECK(pl::segment_hits(r, 15, 15, 16, 16));   // inside
    CHECK_FALSE(pl::segment_hits(r, 0, 40, 40, 35));  // below
    CHECK_FALSE(pl::segment_hits(r, 0, 0, 40, 5));    // above
    CHECK_FALSE(pl::segment_hits(r, 0, 25, 5, 45));   // beside, sloped
    CHECK(pl::segment_hits(r, 20, 0, 20, 100));   // vertical through
}

TEST_CASE("plot legend: the first corner free of data, none when all four have data", "[analysis][plot]") {
    const pl::Rect plot{100, 50, 400, 300};
    pl::DataFootprint top_right;
    top_right.boxes.push_back({480, 60, 6, 6});
    const auto corner = pl::free_legend_corner(plot, 120, 60, top_right);
    REQUIRE(corner);
    CHECK(corner->x < 200);  // moved to the top left
    CHECK(corner->y < 100);
    CHECK_FALSE(top_right.hits(*corner));

    pl::DataFootprint corners;
    corners.segments.push_back({100, 50, 500, 350});   // top left to bottom right
    corners.segments.push_back({100, 350, 500, 50});   // bottom left to top right
    CHECK_FALSE(pl::free_legend_corner(plot, 120, 60, corners));
}

TEST_CASE("plot legend: a parity plot's legend sits clear of points, 95 % bars and the 1:1 line", "[analysis][plot]") {
    pl::XYPanel p;
    p.box = {0, 40, 600, 580};
    p.identity_line = true;
    pl::Series before, after;
    before.label = "before: twin (RMSE 12.30 W/m²)";
    after.label = "after: + gamma (RMSE 3.10 W/m²)";
    for (int i = 0; i < 70; ++i) {
        const double q = -171.0 + 165.0 * i / 69.0;
        before.x.push_back(q);
        before.x_err.push_back(8.0);
        before.y.push_back(q * 0.9 - 6.0);
        after.x.push_back(q);
        after.x_err.push_back(8.0);
        after.y.push_back(q + 1.0);
    }
    p.series = {before, after};
    const auto l = pl::layout_xy(p);
    REQUIRE(l.legend);
    CHECK_FALSE(l.legend_outside);
    CHECK_FALSE(l.data.hits(*l.legend));
    CHECK(l.data.boxes.size() == 140);
    CHECK(l.data.segments.size() == 141);  // 140 bars and the 1:1 line
    CHECK(round_step(l.x_ticks.step));
    CHECK(l.x_ticks.lo == l.y_ticks.lo);  // one range for both axes
    CHECK(l.x_ticks.hi == l.y_ticks.hi);
}

TEST_CASE("plot legend: goes outside, right of the plot, when data fills every corner", "[analysis][plot]") {
    pl::XYPanel p;
    p.box = {0, 0, 700, 400};
    for (int k = 0; k < 4; ++k) {
        pl::Series s;
        s.label = "trace " + std::to_string(k);
        s.line = true;
        s.markers = false;
        for (int i = 0; i <= 120; ++i) {
            s.x.push_back(i);
            s.y.push_back(std::sin(i / 7.0 + k) * 100.0);  // crosses the whole plot
        }
        p.series.push_back(s);
    }
    const auto l = pl::layout_xy(p);
    REQUIRE(l.legend);
    CHECK(l.legend_outside);
    CHECK(l.legend->x >= l.plot.x + l.plot.w);
    CHECK(l.legend->x + l.legend->w <= p.box.x + p.box.w);
    CHECK_FALSE(l.data.hits(*l.legend));
    const std::string svg = pl::to_svg({.width_px = 700, .height_px = 400, .title = "", .xy_panels = {p}, .heat_maps = {}, .notes = {}});
    CHECK(svg.find("class=\"legend\"") != std::string::npos);
    CHECK(svg.find("trace 3") != std::string::npos);
}

TEST_CASE("plot heat map: cells coloured on a symmetric scale with a colour bar and its unit", "[analysis][plot]") {
    pl::Figure f;
    f.width_px = 720;
    f.height_px = 520;
    pl::HeatMapPanel h;
    h.box = {0, 30, 720, 490};
    h.x.label = "Air temperature (°C)";
    h.y.label = "Relative humidity (%)";
    h.scale_label = "Core difference (°C)";
    for (double t = 30; t <= 50; t += 5) h.x_centres.push_back(t);
    for (double rh = 5; rh <= 95; rh += 45) h.y_centres.push_back(rh);
    for (std::size_t i = 0; i < h.x_centres.size() * h.y_centres.size(); ++i) h.values.push_back(-0.4 + 0.1 * static_cast<double>(i));
    f.heat_maps.push_back(h);
    const std::string svg = pl::to_svg(f);
    const auto bar = svg.find("class=\"colour-bar\"");
    REQUIRE(bar != std::string::npos);
    CHECK(svg.find("Core difference (°C)", bar) != std::string::npos);
    // Values -0.4 .. 1.0: a symmetric scale -1 .. 1 with round ticks, 0 (white) in the middle.
    for (const char* tick : {">-1.0<", ">0.0<", ">1.0<"}) {
        INFO(tick);
        CHECK(svg.find(tick, bar) != std::string::npos);
    }
    CHECK(svg.find("Air temperature (°C)") != std::string::npos);
    CHECK(svg.find("Relative humidity (%)") != std::string::npos);
    CHECK(pl::scale_colour(0.5, true) == "#f7f7f7");
    CHECK(pl::scale_colour(0.0, true) == "#2166ac");
    CHECK(pl::scale_colour(1.0, true) == "#b2182b");
    CHECK(pl::scale_colour(2.0, true) == "#b2182b");  // clamped
}

TEST_CASE("body map: every ANDI zone drawn front or back, coloured by its value, grey without one, texts escaped",
          "[analysis][plot]") {
    // The drawing knows exactly the compiled map's zones, 20 in front and 15 behind.
    const auto& map = manikind::analysis::andi35_zone_map();
    REQUIRE(pl::andi_zone_shapes().size() == map.size());
    int front = 0;
    for (const auto& z : map.zones) {
        const auto it = pl::andi_zone_shapes().find(z.name);
        REQUIRE(it != pl::andi_zone_shapes().end());
        front += it->second.front ? 1 : 0;
    }
    CHECK(front == 20);

    // The diverging scale: white at zero, its ends at +-limit, clamped beyond, symmetric.
    CHECK(pl::diverging_colour(0.0, 3.0) == "#ffffff");
    CHECK(pl::diverging_colour(3.0, 3.0) == "#b2182b");
    CHECK(pl::diverging_colour(-3.0, 3.0) == "#2166ac");
    CHECK(pl::diverging_colour(7.0, 3.0) == "#b2182b");
    CHECK(pl::diverging_colour(std::nan(""), 3.0) == "#ffffff");
    CHECK(pl::diverging_colour(1.5, 3.0) != pl::diverging_colour(-1.5, 3.0));

    pl::BodyMap body;
    body.title = "t <&> \"x\"";
    body.scale_label = "σ";
    body.scale_min = -3.0;
    body.scale_max = 3.0;
    body.colour = [](double v) { return pl::diverging_colour(v, 3.0); };
    body.tooltip = [](const std::string& zone, std::optional<double> v) {
        return zone + (v ? " has " + std::to_string(*v) : std::string(" none <b>"));
    };
    pl::BodyMapPanel before, after;
    before.caption = "before & <x>";
    before.value_by_zone["face"] = 3.0;
    before.value_by_zone["calf_back_l"] = -9.0;  // beyond the scale: its end colour
    after.value_by_zone["face"] = 0.0;
    body.panels = {before, after};
    const auto svg = pl::body_map_svg(body);
    auto count = [&svg](const std::string& what) {
        std::size_t n = 0;
        for (auto at = svg.find(what); at != std::string::npos; at = svg.find(what, at + 1)) ++n;
        return n;
    };
    CHECK(count("<title>") == 70);                    // 35 zones in each of the two panels
    CHECK(count(R"(fill="#b2182b" stroke)") == 1);     // the face before
    CHECK(count(R"(fill="#2166ac" stroke)") == 1);     // the left calf's back, clamped
    CHECK(count(R"(fill="#ffffff" stroke)") == 1);     // the face after
    CHECK(count(R"(fill="#dddddd" stroke)") == 67);    // every zone without a value
    CHECK(count("none &lt;b&gt;") == 67);
    CHECK(svg.find("before &amp; &lt;x&gt;") != std::string::npos);
    CHECK(svg.find("t &lt;&amp;&gt;") != std::string::npos);
    CHECK(svg.find("<b>") == std::string::npos);
}
