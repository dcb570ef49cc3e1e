#pragma once
// The library of candidate physics terms reconcile may propose: each with a one-line physical
// rationale, parameters with bounds, the value that means "no effect", a theoretical
// expectation where theory gives one, and the range a physicist would call plausible.
#include <optional>
#include <string>
#include <vector>

namespace manikind::analysis::reconcile {

struct ParameterSpec {
    std::string name;
    std::string unit;
    double lo = 0.0, hi = 0.0;                      // fit bounds
    double start = 0.0;                             // first guess
    double null_value = 0.0;                        // the baseline (no effect)
    std::optional<double> theory;                   // expectation from theory, if any
    double plausible_lo = 0.0, plausible_hi = 0.0;  // outside: rejected as implausible
};

struct CandidateTerm {
    std::string term;           // twin term name (physics/twin)
    std::string region;         // partial_wettedness: which region
    std::string rationale;      // one line of physics
    std::vector<ParameterSpec> parameters;
    std::string label() const { return region.empty() ? term : term + ":" + region; }
};

// The whole library. `regions` are the zone-map regions present (partial wettedness is offered
// once per region that is wet in at least one case).
std::vector<CandidateTerm> candidate_library(const std::vector<std::string>& wet_regions);

// A plain-language statement of what the fitted term says physically.
std::string plain_statement(const CandidateTerm& c, const std::vector<double>& values,
                            const std::vector<double>& uncertainties);

}  // namespace manikind::analysis::reconcile
