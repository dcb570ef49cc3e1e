#pragma once
// The benches' fresh processes: a program run as a user runs it, timed from fork to reaping, with
// the operating system's own accounting of its CPU and peak memory.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

namespace manikind::bench {

struct ChildRun {
    double wall_s = 0, cpu_s = 0, peak_mb = 0;
    int status = -1;  // the exit status; -1 when it did not exit
};

// Reaps `pid`, started at `t0`.
inline ChildRun wait_child(pid_t pid, std::chrono::steady_clock::time_point t0) {
    int status = 0;
    rusage u{};
    wait4(pid, &status, 0, &u);
    ChildRun r;
    r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    r.cpu_s = static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
    r.peak_mb = static_cast<double>(u.ru_maxrss) / 1024.0;
    r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

// `program args...`, its standard output (and, when `quiet_stderr`, its errors) to /dev/null, or
// its standard output to the file `stdout_to` when given.
inline ChildRun run_program(const std::string& program, std::vector<std::string> args, bool quiet_stderr = false,
                            const std::string& stdout_to = "") {
    std::fflush(stdout);  // or the child would print this process's buffer again
    std::vector<char*> argv{const_cast<char*>(program.c_str())};
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const auto t0 = std::chrono::steady_clock::now();
    const pid_t pid = fork();
    if (pid == 0) {
        std::freopen(stdout_to.empty() ? "/dev/null" : stdout_to.c_str(), "w", stdout);
        if (quiet_stderr) std::freopen("/dev/null", "w", stderr);
        execv(program.c_str(), argv.data());
        _exit(127);
    }
    return wait_child(pid, t0);
}

}  // namespace manikind::bench
