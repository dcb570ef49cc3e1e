#pragma once
// The one heat-flux sign convention of every command, report and plot (docs/cli.md). Storage
// terms are the exception and say so: positive = heat stored in the body.
namespace manikind::physics {

inline constexpr const char* heat_flux_sign = "positive = heat lost by the body (skin to environment)";
inline constexpr const char* heat_storage_sign = "storage: positive = heat stored in the body";

}  // namespace manikind::physics
