#pragma once
// A trial's set-up (schema version 7, docs/recorder.md "Set-ups"): the lab, chamber and manikin
// named in [lab], the calibration the numbers depend on (each instrument's Type B specification,
// Tables S1-S2, and the register maps with their probe scaling) and the configuration text.
#include "daemon/core/config.hpp"
#include "daemon/core/recorder/database.hpp"

namespace manikind {

// Throws UserError if a register map cannot be read (the daemon has loaded it already).
recorder::Setup setup_of(const config::Config& config);

}  // namespace manikind
