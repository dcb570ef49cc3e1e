#pragma once
// An analog probe's output as a datalogger digitises it, mapped to the measured quantity:
// value = lo + (hi - lo) (raw - raw_lo) / (raw_hi - raw_lo). EE181 with 0-1 V outputs as
// ordered for this lab: raw mV 0..1000 -> T -40..60 °C, RH 0..100 % (the range is in config).
// Pure.
namespace manikind::protocol {

struct ProbeScaling {
    double raw_lo = 0.0, raw_hi = 1.0, lo = 0.0, hi = 1.0;
    double to_value(double raw) const { return lo + (hi - lo) * (raw - raw_lo) / (raw_hi - raw_lo); }
    double to_raw(double value) const { return raw_lo + (raw_hi - raw_lo) * (value - lo) / (hi - lo); }
};

}  // namespace manikind::protocol
