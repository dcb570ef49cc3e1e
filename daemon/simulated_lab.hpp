#pragma once
// The simulated lab as the configuration describes it (`manikin sim serve` and the daemon's
// acquisition build it from here). Part of the daemon's face to `manikin` (docs/architecture.md).
#include "daemon/config.hpp"
#include "sim/lab/sim_lab.hpp"

namespace manikind {

// The world options of the simulated lab from the configuration: ANDI 35-zone manikin, the
// baseline physics plus [simulation] world_effects, Table S3 enclosure offsets.
sim::SimLabOptions simulated_lab_options(const config::Config& config);

}  // namespace manikind
