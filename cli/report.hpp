#pragma once
// A small result table that prints either as aligned text or as one JSON object, so every
// command offers the same --json contract. Non-finite values are refused, never printed.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace manikind::cli {

struct ReportRow {
    std::string key;     // JSON key, with its unit (h_c_w_m2k)
    std::string label;   // human label
    double value = 0.0;
    std::string unit;
    int decimals = 3;
};

class Report {
public:
    explicit Report(std::string title) : title_(std::move(title)) {}
    void add(std::string key, std::string label, double value, std::string unit, int decimals = 3);
    void add_text(std::string key, std::string label, std::string text);
    void warn(const std::string& message) { warnings_.push_back(message); }
    void warn_all(const std::vector<std::string>& messages);
    // Prints to stdout; warnings go to stderr in text mode and into "warnings" in JSON mode.
    void print(bool json) const;
    nlohmann::json to_json() const;

private:
    std::string title_;
    std::vector<ReportRow> rows_;
    std::vector<std::pair<std::pair<std::string, std::string>, std::string>> texts_;
    std::vector<std::string> warnings_;
};

}  // namespace manikind::cli
