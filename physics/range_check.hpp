#pragma once
// Inputs outside a correlation's stated range are not silently extrapolated: functions that
// accept them return a value together with warnings that the CLI prints, and functions whose
// inputs are non-physical (RH < 0, negative speed) throw std::domain_error with the name of
// the input and the range expected.
#include <cmath>
#include <string>
#include <vector>

namespace manikind::physics {

struct Checked {
    double value = 0.0;
    std::vector<std::string> warnings;  // empty when every input was inside the stated range
};

[[noreturn]] void throw_out_of_range(const char* name, double value, double lo, double hi, const char* unit);

// Throws std::domain_error("<name> = <value> <unit> is outside <lo>..<hi> <unit>") unless lo <= value <= hi
// and value is finite. Inline: the twin checks its inputs millions of times per reconcile.
inline void require_in_range(const char* name, double value, double lo, double hi, const char* unit) {
    if (std::isfinite(value) && value >= lo && value <= hi) return;
    throw_out_of_range(name, value, lo, hi, unit);
}

// Appends a warning to `warnings` when value lies outside [lo, hi] (the correlation's stated range).
void warn_if_outside(std::vector<std::string>& warnings, const char* name, double value, double lo,
                     double hi, const char* unit, const char* source);

}  // namespace manikind::physics
