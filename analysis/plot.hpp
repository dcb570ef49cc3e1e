#pragma once
// A figure for a paper: one panel per case, whole-body and regional Q with 95 % error bars
// (± U, Eq. S7), as self-contained SVG (no Python, no plotting library).
#include <filesystem>
#include <string>

#include "analysis/analyze.hpp"

namespace manikind::analysis {

std::string results_svg(const CampaignResult& result);

// Writes the SVG; when `png` is given and rsvg-convert is on PATH, also renders a PNG.
// Returns a note for the user ("PNG written", or why not).
std::string write_results_plot(const CampaignResult& result, const std::filesystem::path& svg_path,
                               const std::filesystem::path& png_path = {});

}  // namespace manikind::analysis
