#pragma once
// Fixed-point fields to engineering units without binary noise. A register or CAN field that
// counts hundredths holds a decimal number; `raw * 0.01` gives the double nearest to
// raw x (0.01's binary approximation), e.g. -60 * 0.01 = -0.6000000000000001, which every
// export and display then shows. `raw / 100` is the double nearest to the decimal itself
// (IEEE division is correctly rounded), so the shortest text that reads it back is "-0.6".
#include <cmath>

namespace manikind::protocol {

// raw x scale + offset; when scale is 1/n for an integer n (0.1, 0.01, 0.5 ...), divides by n.
inline double scaled_value(double raw, double scale, double offset = 0.0) {
    if (scale != 0.0 && std::fabs(scale) < 1.0) {
        const double divisor = 1.0 / scale;
        const double rounded = std::round(divisor);
        if (std::fabs(divisor - rounded) <= 1e-9 * std::fabs(rounded)) return raw / rounded + offset;
    }
    return raw * scale + offset;
}

}  // namespace manikind::protocol
