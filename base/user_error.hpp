#pragma once
// An error the user can act on: bad input, bad file, out-of-range value, a daemon that does not
// answer or refuses, a check whose verdict is negative. It carries a stable snake_case code and
// the exit status the CLI ends with (docs/cli.md); anything else that escapes is a bug (status 1).
#include <string>
#include <stdexcept>
#include <utility>

#include <nlohmann/json.hpp>

namespace manikind {

// The exit statuses of `manikin`, the same for every command (docs/cli.md).
enum class ExitStatus : int {
    ok = 0,
    internal = 1,      // a bug: an exception nobody meant to throw
    bad_input = 2,     // usage or input error: bad option, bad file, bad value
    unreachable = 3,   // the daemon is not reachable or did not answer in time
    refused = 4,       // the daemon or the [safety] / register-map limits refused the request
    negative = 5,      // the command ran and its verdict is negative (a check found problems)
    not_done = 6,      // a campaign waited for ended aborted, failed or interrupted, or with a trial not done
};

class UserError : public std::runtime_error {
public:
    // The default keeps every `throw UserError(msg)` an input error with status 2.
    explicit UserError(const std::string& message, std::string code = "bad_input",
                       ExitStatus status = ExitStatus::bad_input, nlohmann::json details = nullptr)
        : std::runtime_error(message), code_(std::move(code)), status_(status), details_(std::move(details)) {}

    static UserError unreachable(const std::string& message, std::string code = "daemon_unreachable") {
        return UserError(message, std::move(code), ExitStatus::unreachable);
    }
    // `details`: what the command did before the refusal (e.g. probe's readings), for --json.
    static UserError refused(const std::string& message, nlohmann::json details = nullptr) {
        return UserError(message, "refused", ExitStatus::refused, std::move(details));
    }
    // `details`: the full verdict (e.g. selfcheck's table), for --json.
    static UserError check_failed(const std::string& message, nlohmann::json details = nullptr) {
        return UserError(message, "check_failed", ExitStatus::negative, std::move(details));
    }
    // `details`: the campaign's outcome (state, trials by state).
    static UserError campaign_not_done(const std::string& message, nlohmann::json details = nullptr) {
        return UserError(message, "campaign_not_done", ExitStatus::not_done, std::move(details));
    }

    // A negative verdict the command's output already carries (its --json document has it): the
    // CLI ends with status 5 and, in text mode, one line on stderr; no second JSON document.
    static UserError verdict_in_output(const std::string& message) {
        return UserError(message, "verdict_in_output", ExitStatus::negative);
    }

    const std::string& code() const { return code_; }
    ExitStatus status() const { return status_; }
    int exit_code() const { return static_cast<int>(status_); }
    const nlohmann::json& details() const { return details_; }

private:
    std::string code_;
    ExitStatus status_;
    nlohmann::json details_;
};

}  // namespace manikind
