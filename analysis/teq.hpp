#pragma once
// Equivalent temperature after ISO 14505-2 (docs/comfort.md): the temperature of a uniform
// enclosure (air = mean radiant temperature, still air) in which a zone would lose the heat it
// loses in the real, non-uniform environment.
//
//   calibration (uniform chamber, several cases):  q_z = h_cal,z (t_sk,z - t_eq,ref)
//       least squares through the origin over the calibration trials: h = sum x q / sum x²,
//       x = t_sk - t_eq,ref, t_eq,ref = (t_air + t_wall) / 2 (the two agree within the limits)
//   measurement:                                    teq_z = t_sk,z - q_z / h_cal,z
//   region and whole body: the uniform temperature in which the part loses the heat its zones
//       lose together: sum A_z h_z (t_sk,z - teq) = sum A_z q_z, i.e. teq weighted by A_z h_z.
//
// Uncertainty as the other analyses (analysis/clothing.hpp): Type A from the replicates (and, for
// h, the fit's residuals), Type B from the instruments' specs by Monte Carlo (GUM Supplement 1).
// The manikin's skin-temperature and heat-flux errors are drawn once per draw and applied to the
// calibration's data and the measurement's alike (the same manikin measured both: a flux gain
// error scales h and q together and cancels in q/h); the chamber's air and wall probes enter
// through h only.
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"
#include "analysis/plot/svg_figure.hpp"

namespace manikind::analysis::teq {

// The calibration file's format (docs/formats.md section 7); a reader refuses any other.
inline constexpr const char* kCalibrationFormat = "manikin-teq-calibration/1";

// The reference environment's uniformity (ours, docs/comfort.md "Calibration"): checked per
// calibration trial on its steady-window means; a trial outside either refuses the calibration.
struct Limits {
    double max_wall_air_difference_k = 0.5;
    double max_air_speed_m_s = 0.10;
};

struct Options {
    int monte_carlo_draws = 2000;
    // h_cal read at the zone's own temperature difference from the calibration's curve (q = a x +
    // b x|x| over its trials; docs/comfort.md, "h_cal's curve"); false: ISO 14505-2's constant.
    bool curved_h = true;
    unsigned seed = 20261129;
    double confidence = 0.95;
};

// A value with Type A (replicates), Type B (instruments, Monte Carlo), combined, Welch-
// Satterthwaite dof, k and U95, as clothing::Value.
struct Value {
    double value = 0.0;
    double u_a = 0.0;   // NaN when not estimable (one replicate, one calibration point)
    double u_b = 0.0;
    double u_c = 0.0;
    double dof = 0.0;   // 1e9 stands for infinite
    double k = 2.0;
    double U95 = 0.0;
};

// One calibration trial's steady-window means, as the file keeps them (so a reader can refit
// and the teq command can redraw the instrument errors through the fit).
struct CalibrationTrial {
    std::string id;
    int case_id = 0;
    double air_temp_c = 0.0, wall_temp_c = 0.0, air_speed_m_s = 0.0;
    std::vector<double> skin_temp_c, q_w_m2;  // per zone
};

struct ZoneCoefficient {
    int zone = 0;
    std::string name, region;
    double area_m2 = 0.0;
    Value h;                         // W/m²K; u_a from the fit residuals (n - 1 dof)
    double residual_sd_w_m2 = 0.0;   // scatter of q about the fitted line
    int points = 0;
};

struct Calibration {
    std::string format = kCalibrationFormat;
    std::string campaign;            // the calibration campaign's name
    std::string program;             // e.g. "manikind 0.1.0"
    std::string created_utc;
    Limits limits;
    std::map<std::string, InstrumentSpec> instruments;  // skin_temp_c, heat_flux_w_m2, air_temp_c, wall_temp_c
    std::vector<CalibrationTrial> trials;
    std::vector<ZoneCoefficient> zones;
    Value h_whole_body;              // sum f_z h_z, for reading only
    int draws = 0;
    std::vector<std::string> warnings;
};

// Fits the calibration. Throws std::invalid_argument naming the case, trial and quantity when the
// environment was not uniform within `limits`, a quantity the check needs was not recorded, or a
// zone has nothing to fit.
Calibration calibrate(const Campaign& campaign, const CampaignResult& analysis, const Limits& limits,
                      const Options& options = {});

nlohmann::json to_json(const Calibration& c);
std::string to_text(const Calibration& c);
// Reads a calibration file; InputError naming the file, the line (parse errors) and the field.
Calibration read_calibration(const std::filesystem::path& file);
Calibration calibration_from_json(const nlohmann::json& j, const std::string& file);

// Neutral ranges of teq per part: a zone's name, a region's name or "whole_body".
struct Range {
    double cold_limit_c = 0.0, warm_limit_c = 0.0;
};
struct NeutralRanges {
    std::map<std::string, Range> parts;
    std::string source;
    bool placeholder = false;
};
// Placeholders, not from a source (docs/comfort.md "Neutral ranges"): every part 21..26 °C.
NeutralRanges placeholder_ranges(const ZoneMap& map);
// CSV `part,cold_limit_c,warm_limit_c` with that header; InputError naming file, line and field.
NeutralRanges read_ranges(const std::filesystem::path& file);

struct PartTeq {
    std::string name;
    double area_m2 = 0.0;
    Value teq;                       // °C
    double skin_temp_c = 0.0;        // area-weighted
    double q_w_m2 = 0.0;             // area-weighted
    std::optional<Range> neutral;
    std::string verdict;             // "cold", "neutral", "warm", "cold?"/"warm?" (the interval straddles a limit), "" (no range)
};

struct CaseTeq {
    int case_id = 0;
    int replicates = 0;
    double air_temp_c = 0.0, wall_temp_c = 0.0, air_speed_m_s = 0.0;  // NaN when not recorded
    std::vector<PartTeq> zones, regions;
    PartTeq whole_body;
    std::vector<std::string> notes;
};

struct Result {
    std::string campaign, calibration_campaign;
    Options options;
    NeutralRanges ranges;
    std::vector<CaseTeq> cases;
    std::vector<std::string> warnings;
};

// Throws std::invalid_argument when the calibration does not fit the campaign's zone map or no
// case has a steady trial.
Result compute(const Campaign& campaign, const CampaignResult& analysis, const Calibration& calibration,
               const NeutralRanges& ranges, const Options& options = {});

nlohmann::json to_json(const Result& r);
std::string to_text(const Result& r);
// The comfort-zone diagram: per case, each zone's teq ± U95 against its neutral range.
plot::Figure comfort_figure(const Result& r);
// A page for the reader (`manikin teq --report`): which campaign and calibration, when, by which
// program and standard, the whole body and regions per case, the diagram, every zone, the notes
// and warnings. HTML with the diagram's SVG inline, nothing fetched.
std::string report_html(const Result& r, const std::string& generated_utc, const std::string& program);

}  // namespace manikind::analysis::teq
