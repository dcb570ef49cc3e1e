#pragma once
// Reconcile's outputs: the JSON contract of docs/formats.md section 3 (`manikin reconcile --json`), a readable
// text report, and SVG plots (parity with 95 % error bars before/after, residual vs driver).
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/reconcile/reconcile.hpp"

namespace manikind::analysis::reconcile {

nlohmann::json report_to_json(const Report& report, const ForwardModel& model);
std::string report_to_text(const Report& report);
nlohmann::json power_to_json(const PowerReport& plan);
std::string power_to_text(const PowerReport& plan);

// The names write_plots writes in its folder (for a caller to check them before it runs).
std::vector<std::string> plot_file_names();

// Writes parity.svg (Q_sim vs Q_exp with 95 % error bars, before and after) and
// residual_vs_driver.svg into `dir` (created if missing); returns the paths written.
std::vector<std::filesystem::path> write_plots(const Report& report, const ForwardModel& model,
                                               const std::filesystem::path& dir, const std::string& unit = "W/m²");

}  // namespace manikind::analysis::reconcile
