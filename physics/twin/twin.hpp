#pragma once
// The digital twin: per-zone steady heat flux from the recorded conditions of a trial, with an
// explicit, named list of physics terms. The baseline is docs/twin-baseline.md (temperature-driven
// free convection, grey radiation, Lewis-relation evaporation); every other twin version is the
// baseline plus terms with parameters. Pure: no I/O. Flux positive = heat lost by the manikin.
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace manikind::physics::twin {

// Baseline constants per manikin segment (docs/twin-baseline.md steps 2-3), kept in one place.
struct SegmentConstants {
    std::string segment;
    double wissler_a = 0.0;          // h_c = A |dT|^(1/4), Table 2 (Wissler)
    double radiating_fraction = 0.0; // f in q_rad
};
const std::vector<SegmentConstants>& baseline_segments();
std::optional<SegmentConstants> baseline_segment(const std::string& segment);

inline constexpr double baseline_skin_emissivity = 0.98;  // Text S3.3
inline constexpr double baseline_lewis_k_kpa = 16.5;      // Eq. 1

// The room one zone meets where it is not uniform (ISO 14505-2's subject: a vehicle cabin, a desk by
// a cold window): offsets from what the chamber's probes read, the air's speed at the zone, and
// heat that is neither convection, radiation nor evaporation. All zero and no speed: the uniform
// enclosure of the paper. A lab states them per case (campaign `[[cases.local]]`); the simulated
// world takes its own from `[[simulation.local]]` (docs/comfort.md, "A non-uniform room").
struct LocalEnvironment {
    double air_offset_c = 0.0;               // the air at the zone minus the probes' reading
    double radiant_offset_c = 0.0;           // the zone's mean radiant temperature minus the walls'
    std::optional<double> air_speed_m_s{};   // the air's speed at the zone (a vent jet); none: the room's
    double contact_w_m2 = 0.0;               // conducted into what the zone touches (a seat); < 0: a heated seat gives
    double solar_w_m2 = 0.0;                 // short-wave absorbed (sun through glass), which the zone does not lose
    bool uniform() const {
        return air_offset_c == 0.0 && radiant_offset_c == 0.0 && !air_speed_m_s && contact_w_m2 == 0.0 && solar_w_m2 == 0.0;
    }
    bool operator==(const LocalEnvironment&) const = default;
};

struct ZoneInput {
    int zone = 0;
    std::string segment;        // zone map segment (head, chest, ..., foot)
    std::string region;         // zone map region (head, chest, upper_arm_l, ...)
    double area_m2 = 0.0;
    double skin_temp_c = 35.0;
    // Geometry (zone map), for the input_pattern term: centroid height above the floor, which
    // way the zone faces (+1 front, -1 back, 0 neither) and its side (-1 left, +1 right, 0 centre).
    std::optional<double> height_m{};
    int facing = 0;
    int side = 0;
    LocalEnvironment local{};
};

struct TrialConditions {
    double air_temp_c = 35.0;
    double air_rh_pct = 50.0;
    std::optional<double> wall_temp_c;    // equal to air where not recorded
    std::optional<double> air_speed_m_s;  // 0 where not recorded
    double wettedness = 0.0;              // campaign: wet -> 1, dry -> 0
    std::vector<ZoneInput> zones;
    // Per zone (same order as zones), where the sweat is metered zone by zone (a manikin under a
    // thermoregulation model's control); empty: every zone has `wettedness`.
    std::vector<double> zone_wettedness;
};

// A physics term: a name from the library and its parameters. `zones` and `region` scope a
// term to part of the body where the term allows it (partial_wettedness, heat_leak).
struct Term {
    std::string name;
    std::map<std::string, double> parameters;
    std::string region;            // partial_wettedness: the zone-map region it applies to
    std::vector<int> zones;        // heat_leak: the zones it applies to
    // input_pattern: which input the twin takes is off (input_names()) and by which pattern over
    // the body (pattern_names()); its parameter `value` is the size, in the input's unit (per
    // metre for "height", relative to the probe's height `ref_height_m`); for air_speed_m_s a
    // fraction of the anemometer's reading (the zone meets the reading x (1 + value x pattern)).
    std::string input{};
    std::string pattern{};
};

// The inputs and patterns an input_pattern term may name.
const std::vector<std::string>& input_names();    // air_temp_c, wall_temp_c, vapour_pressure_pa, wettedness, heat_flux_w_m2, air_speed_m_s
const std::vector<std::string>& pattern_names();  // uniform, height, front, back, left, right
// The weight of a pattern at one zone (0 where the pattern does not reach it); throws
// std::invalid_argument for "height" on a zone without a height.
double pattern_weight(const std::string& pattern, const ZoneInput& zone, double ref_height_m);

struct TwinVersion {
    std::string name = "baseline";
    std::vector<Term> terms;       // applied on top of the baseline
};

struct ZoneFlux {
    int zone = 0;
    double h_c_w_m2k = 0.0;
    double q_convection_w_m2 = 0.0;
    double q_radiation_w_m2 = 0.0;
    double q_evaporation_w_m2 = 0.0;
    double q_other_w_m2 = 0.0;     // e.g. heat_leak
    double q_total_w_m2 = 0.0;
    double surface_temp_c = 0.0;   // exchange surface (textile) temperature
};

// Every term the twin knows, with its parameters; throws std::invalid_argument for an unknown
// term or parameter (message names it and lists the known ones).
void validate_term(const Term& term);

// Predicts every zone of one trial. Throws std::invalid_argument for an unknown segment or term.
std::vector<ZoneFlux> predict(const TwinVersion& version, const TrialConditions& trial);

// A version's terms read and checked once (validate_term on each), for a caller that predicts many
// trials with one version: reconcile's forward model does so thousands of times per campaign, and
// reading the terms' names for every trial was a tenth of its time (issue 62).
struct ResolvedVersion {
    double gamma = 0.0;
    double h0_w_m2k = 0.0;
    double forced_scale = 0.0;
    double wall_offset_c = 0.0;
    double air_bias_c = 0.0;
    double textile_r_m2k_w = 0.0;
    std::vector<std::pair<std::string, double>> wettedness_by_region;
    std::vector<std::pair<std::vector<int>, double>> leaks;
    std::vector<std::pair<std::vector<int>, double>> gains;
    struct Garment {
        std::string region;
        double icl_m2k_w = 0.0, recl_m2kpa_w = 0.0, fcl = 1.0;
    };
    std::vector<Garment> garments;
    struct Pattern {
        std::string input, pattern;
        double value = 0.0, ref_height_m = 1.1;
        // The two names read once by resolve(), not compared per zone and prediction.
        enum class Input { air, wall, vapour, wettedness, heat_flux, air_speed, other } input_kind = Input::other;
        enum class Shape { uniform, height, front, back, left, right, other } shape = Shape::other;
    };
    std::vector<Pattern> patterns;  // input_pattern terms
};
ResolvedVersion resolve(const TwinVersion& version);  // throws as predict does for an unknown term

// predict() into `out` (resized to the trial's zones, its storage reused). With `only` (one flag
// per zone), only the flagged zones are computed and the others left as they were: a zone's flux
// depends on its own inputs and the version alone, so a flagged zone's value is the same number
// predict() gives it.
void predict(const ResolvedVersion& version, const TrialConditions& trial, std::vector<ZoneFlux>& out,
             const std::vector<char>* only = nullptr);

// Area-weighted mean of the zone totals (regions and whole body, as for measurements).
double area_weighted_mean_w_m2(const std::vector<ZoneFlux>& fluxes, const std::vector<ZoneInput>& zones,
                               const std::vector<int>& zone_ids);

}  // namespace manikind::physics::twin
