// Start-up of the quick commands (issue 36, item 4): `manikin --version`, `status` and `live`
// against an idle daemon on the simulated lab, each a fresh process, beside the floor measured in
// the same run: an empty C++ program (bench/floors/empty_program.cpp) started the same way. The
// four are started in turn, round after round, so a drift of the machine's speed touches each
// alike; the medians are printed with what each costs beyond the floor (the goal: under 3 ms).
//   bench_startup [rounds, default 60]
#include <fcntl.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "base/lazy_library.hpp"

extern char** environ;

namespace fs = std::filesystem;

namespace {

// Starts `argv` with stdout and stderr on /dev/null; its pid.
pid_t spawn_quiet(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    pid_t pid = -1;
    if (posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ) != 0) pid = -1;
    posix_spawn_file_actions_destroy(&actions);
    return pid;
}

// Wall milliseconds from the spawn to the reaped exit; negative when it did not exit 0.
double timed_run(const std::vector<std::string>& args) {
    const auto t0 = std::chrono::steady_clock::now();
    const pid_t pid = spawn_quiet(args);
    int status = 0;
    if (pid < 0 || waitpid(pid, &status, 0) != pid) return -1;
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return WIFEXITED(status) && WEXITSTATUS(status) == 0 ? ms : -ms;
}

bool socket_answers(const fs::path& path) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::snprintf(a.sun_path, sizeof a.sun_path, "%s", path.c_str());
    const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    ::close(fd);
    return ok;
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
    const int rounds = argc > 1 ? std::max(5, std::atoi(argv[1])) : 60;
    const std::string bin = manikind::LazyLibrary::program_directory();
    const fs::path dir = fs::temp_directory_path() / ("manikind-bench-startup-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path sock = dir / "m.sock";
    const pid_t daemon = spawn_quiet({bin + "/manikind", "--socket", sock.string(), "--database", (dir / "m.db").string()});
    // Waits for the daemon's socket (a bench, not a test: a bounded poll is enough here).
    for (int i = 0; i < 600 && !socket_answers(sock); ++i) ::usleep(50'000);
    if (daemon < 0 || !socket_answers(sock)) {
        std::fprintf(stderr, "bench_startup: the daemon did not start (%s/manikind)\n", bin.c_str());
        return 1;
    }
    const std::string manikin = bin + "/manikin";
    struct Command {
        const char* label;
        std::vector<std::string> args;
        std::vector<double> ms;
    };
    std::vector<Command> commands{
        {"empty C++ program (floor)", {bin + "/bench_floor_empty_program"}, {}},
        {"manikin --version", {manikin, "--version"}, {}},
        {"manikin status", {manikin, "status", "--socket", sock.string()}, {}},
        {"manikin live", {manikin, "live", "--socket", sock.string()}, {}},
    };
    for (auto& c : commands) timed_run(c.args);  // a warm-up each: page cache and dynamic loader cache
    int failures = 0;
    for (int r = 0; r < rounds; ++r)
        for (auto& c : commands) {
            const double ms = timed_run(c.args);
            if (ms < 0) ++failures;
            c.ms.push_back(std::abs(ms));
        }
    ::kill(daemon, SIGTERM);
    waitpid(daemon, nullptr, 0);
    fs::remove_all(dir);

    const double floor_ms = median(commands.front().ms);
    std::printf("start-up, %d rounds, each command a fresh process (median wall ms; the goal: under 3 ms beyond the floor)\n", rounds);
    for (const auto& c : commands) {
        const double m = median(c.ms);
        if (&c == &commands.front())
            std::printf("  %-28s %6.2f ms\n", c.label, m);
        else
            std::printf("  %-28s %6.2f ms   %+5.2f ms beyond the floor%s\n", c.label, m, m - floor_ms, m - floor_ms < 3.0 ? "" : "  (over the goal)");
    }
    if (failures) std::printf("  %d runs did not exit 0\n", failures);
    return failures ? 1 : 0;
}
