#pragma once
// A trial's set-up (schema version 7, docs/recorder.md "Set-ups"): the lab, chamber and manikin
// named in [lab], the calibration the numbers depend on (each instrument's Type B specification,
// Tables S1-S2, and the register maps with their probe scaling) and the configuration text.
#include <string>

#include "daemon/config.hpp"
#include "store/database.hpp"

namespace manikind {

// Throws UserError if a register map cannot be read (the daemon has loaded it already). The
// configuration text is stored with its secrets redacted (redact_secrets).
recorder::Setup setup_of(const config::Config& config);

// The TOML text with the value of [api] token, and of [archive] postgresql when it carries a
// password, replaced by "(redacted)"; everything else as written. Text that does not parse
// gives "" (where the secrets are cannot be told).
std::string redact_secrets(const std::string& toml_text);

}  // namespace manikind
