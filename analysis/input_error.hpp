#pragma once
// Bad input in a recording: names the file, line and column (1-based; 0 when not known) and
// the field. The analysis layer does not know the daemon; the CLI turns this into a
// manikind::UserError (exit status 2) with the same message.
#include <stdexcept>
#include <string>

namespace manikind::analysis {

class InputError : public std::runtime_error {
public:
    InputError(std::string file, std::size_t line, std::size_t column, std::string field, const std::string& what);
    const std::string& file() const { return file_; }
    std::size_t line() const { return line_; }
    std::size_t column() const { return column_; }
    const std::string& field() const { return field_; }

private:
    std::string file_;
    std::size_t line_;
    std::size_t column_;
    std::string field_;
};

}  // namespace manikind::analysis
