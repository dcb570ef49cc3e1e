#include "cli/report.hpp"

#include <cmath>
#include <cstdio>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "base/user_error.hpp"

namespace manikind::cli {

void Report::add(std::string key, std::string label, double value, std::string unit, int decimals) {
    if (!std::isfinite(value))
        throw UserError(fmt::format("{} is not defined for these inputs (computed {})", label, value));
    rows_.push_back({std::move(key), std::move(label), value, std::move(unit), decimals});
}

void Report::add_text(std::string key, std::string label, std::string text) {
    texts_.push_back({{std::move(key), std::move(label)}, std::move(text)});
}

void Report::warn_all(const std::vector<std::string>& messages) {
    for (const auto& m : messages) warn(m);
}

nlohmann::json Report::to_json() const {
    nlohmann::json out = nlohmann::json::object();
    for (const auto& [names, text] : texts_) out[names.first] = text;
    for (const auto& row : rows_) out[row.key] = row.value;
    out["warnings"] = warnings_;
    return out;
}

void Report::print(bool json) const {
    if (json) {
        std::printf("%s\n", to_json().dump(2).c_str());
        return;
    }
    for (const auto& w : warnings_) spdlog::warn("{}", w);
    std::size_t width = 0;
    for (const auto& row : rows_) width = std::max(width, row.label.size());
    for (const auto& [names, text] : texts_) width = std::max(width, names.second.size());
    std::printf("%s\n", title_.c_str());
    for (const auto& [names, text] : texts_)
        std::printf("  %-*s  %s\n", static_cast<int>(width), names.second.c_str(), text.c_str());
    for (const auto& row : rows_) {
        const std::string number = std::abs(row.value) >= 1e6 || (row.value != 0.0 && std::abs(row.value) < 1e-3)
                                       ? fmt::format("{:.4g}", row.value)
                                       : fmt::format("{:.{}f}", row.value, row.decimals);
        std::printf("  %-*s  %12s %s\n", static_cast<int>(width), row.label.c_str(), number.c_str(), row.unit.c_str());
    }
}

}  // namespace manikind::cli
