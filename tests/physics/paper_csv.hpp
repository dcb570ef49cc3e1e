#pragma once
// Reads the paper's tables shipped in tests/data/paper/*.csv (copied from the paper's
// supplement; see tests/data/paper/README.md) into rows of named cells.
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace manikind::test {

using CsvRow = std::map<std::string, std::string>;

inline std::vector<CsvRow> read_paper_csv(const std::string& file_name) {
    const std::string path = std::string(MANIKIND_TEST_DATA_DIR) + "/paper/" + file_name;
    std::ifstream in(path);
    if (!in) throw std::runtime_error("cannot open " + path);
    auto split = [](const std::string& line) {
        std::vector<std::string> cells;
        std::stringstream ss(line);
        std::string cell;
        while (std::getline(ss, cell, ',')) cells.push_back(cell);
        if (!line.empty() && line.back() == ',') cells.emplace_back();
        return cells;
    };
    std::string line;
    std::getline(in, line);
    const auto header = split(line);
    std::vector<CsvRow> rows;
    while (std::getline(in, line)) {
        if (line.empty()) continue;
        const auto cells = split(line);
        CsvRow row;
        for (std::size_t i = 0; i < header.size(); ++i) row[header[i]] = i < cells.size() ? cells[i] : "";
        rows.push_back(std::move(row));
    }
    return rows;
}

inline double num(const CsvRow& row, const std::string& key) { return std::stod(row.at(key)); }

}  // namespace manikind::test
