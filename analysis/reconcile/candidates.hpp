#pragma once
// The library of candidate physics terms reconcile may propose: each with a one-line physical
// rationale, parameters with bounds, the value that means "no effect", a theoretical
// expectation where theory gives one, and the range a physicist would call plausible.
#include <optional>
#include <string>
#include <vector>

#include "physics/twin/twin.hpp"

namespace manikind::analysis::reconcile {

struct ParameterSpec {
    std::string name;
    std::string unit;
    double lo = 0.0, hi = 0.0;                      // fit bounds
    double start = 0.0;                             // first guess
    double null_value = 0.0;                        // the baseline (no effect)
    std::optional<double> theory;                   // expectation from theory, if any
    double plausible_lo = 0.0, plausible_hi = 0.0;  // outside: named with advice, never refused
};

struct CandidateTerm {
    std::string term;           // twin term name (physics/twin)
    std::string region;         // partial_wettedness: which region
    std::string rationale;      // one line of physics
    std::vector<ParameterSpec> parameters;
    std::vector<int> zones;     // heat_leak: the zone(s) it applies to (local anomalies)
    // input_pattern (a generated hypothesis): the twin's input that is off and its pattern over
    // the body (physics/twin/twin.hpp, input_names() and pattern_names()).
    std::string input{}, pattern{};
    bool generated() const { return term == "input_pattern"; }
    std::string label() const {
        if (generated()) return term + ":" + input + "/" + pattern;
        if (!zones.empty()) {
            std::string z;
            for (int id : zones) z += (z.empty() ? "" : ",") + std::to_string(id);
            return term + ":zone " + z;
        }
        return region.empty() ? term : term + ":" + region;
    }
};

// Candidate terms with their parameter values (in order) as twin terms.
std::vector<physics::twin::Term> to_twin_terms(const std::vector<CandidateTerm>& terms, const std::vector<double>& values);

// The whole library. `regions` are the zone-map regions present (partial wettedness is offered
// once per region that is wet in at least one case).
std::vector<CandidateTerm> candidate_library(const std::vector<std::string>& wet_regions);

// What the body's geometry lets patterns say: zones at more than one height, zones facing front
// and back, zones on the left and right; whether any case is wet.
struct GeometryKnown {
    bool height = false, facing = false, sides = false, wet = false;
    bool air_moves = false;  // a case with recorded air speed: the air's speed by pattern can matter
};

// Hypotheses generated from the twin's inputs and the body's geometry (issue 61): each input
// that can be off by a pattern that the geometry can show. The default family takes the
// pairings a chamber makes physically (docs/reconcile.md, "Generated hypotheses"); `all`: every
// input with every pattern (a larger family: a higher claim threshold, so less power).
std::vector<CandidateTerm> generated_hypotheses(const GeometryKnown& geometry, bool all = false);

// A physical phrase for an input_pattern's reading, e.g. "a vertical air-temperature gradient".
std::string pattern_phrase(const CandidateTerm& c);

// Advice where a fitted value is unusual (outside the plausible range, or unlike theory). It
// never removes a candidate: the best term is named with the warning.
std::vector<std::string> plausibility_advice(const CandidateTerm& c, const std::vector<double>& values,
                                             const std::vector<double>& uncertainties);

// A plain-language statement of what the fitted term says physically.
std::string plain_statement(const CandidateTerm& c, const std::vector<double>& values,
                            const std::vector<double>& uncertainties);

}  // namespace manikind::analysis::reconcile
