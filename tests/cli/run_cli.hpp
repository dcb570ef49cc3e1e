#pragma once
// Runs build/bin/manikin as a user would and captures stdout and the exit status.
#include <array>
#include <cstdio>
#include <string>
#include <sys/wait.h>

namespace manikind::test {

struct CliResult {
    int exit_code = -1;
    std::string out;  // stdout (stderr goes to the test log)
};

inline CliResult run_manikin(const std::string& args) {
    const std::string command = std::string(MANIKIND_BIN_DIR) + "/manikin " + args;
    CliResult r;
    FILE* pipe = popen(command.c_str(), "r");
    if (!pipe) return r;
    std::array<char, 4096> buf{};
    std::size_t n = 0;
    while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
    const int status = pclose(pipe);
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

}  // namespace manikind::test
