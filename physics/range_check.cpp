#include "physics/range_check.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace manikind::physics {

void throw_out_of_range(const char* name, double value, double lo, double hi, const char* unit) {
    std::ostringstream msg;
    msg << name << " = " << value << ' ' << unit << " is outside " << lo << ".." << hi << ' ' << unit;
    throw std::domain_error(msg.str());
}

void warn_if_outside(std::vector<std::string>& warnings, const char* name, double value, double lo,
                     double hi, const char* unit, const char* source) {
    if (value >= lo && value <= hi) return;
    std::ostringstream msg;
    msg << name << " = " << value << ' ' << unit << " is outside the range " << lo << ".." << hi << ' '
        << unit << " of " << source << "; the value is extrapolated";
    warnings.push_back(msg.str());
}

}  // namespace manikind::physics
