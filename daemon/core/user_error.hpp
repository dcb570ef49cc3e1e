#pragma once
// An error the user can act on: bad input, bad file, out-of-range value. The CLI prints
// its message and exits with status 2; anything else that escapes is a bug (status 1).
#include <stdexcept>
#include <string>

namespace manikind {

class UserError : public std::runtime_error {
public:
    explicit UserError(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace manikind
