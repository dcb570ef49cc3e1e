#pragma once
// The real daemon binary as a child process: stdout and stderr on a pipe (reading it blocks on
// real events, never on a sleep), optional extra environment and open-file limit.
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

extern char** environ;

namespace manikind::test {

class DaemonProcess {
public:
    struct Options {
        std::map<std::string, std::string> env;  // added to (or replacing in) the test's environment
        rlim_t max_open_files = 0;               // 0: inherit
    };

    static DaemonProcess spawn(const std::vector<std::string>& args) { return spawn(args, Options()); }
    static DaemonProcess spawn(const std::vector<std::string>& args, const Options& options) {
        // Everything the child needs is built before fork: after it, only exec-safe calls.
        std::vector<std::string> env_strings;
        for (char** e = environ; *e; ++e) {
            const std::string kv = *e;
            if (!options.env.count(kv.substr(0, kv.find('=')))) env_strings.push_back(kv);
        }
        for (const auto& [k, v] : options.env) env_strings.push_back(k + "=" + v);
        std::vector<char*> envp, argv;
        for (auto& e : env_strings) envp.push_back(e.data());
        envp.push_back(nullptr);
        std::vector<std::string> args_copy = args;
        for (auto& a : args_copy) argv.push_back(a.data());
        argv.push_back(nullptr);
        int fds[2];
        if (::pipe(fds) != 0) return {};
        const pid_t pid = ::fork();
        if (pid == 0) {
            ::dup2(fds[1], STDOUT_FILENO);
            ::dup2(fds[1], STDERR_FILENO);
            ::close(fds[0]);
            ::close(fds[1]);
            if (options.max_open_files > 0) {
                rlimit lim{options.max_open_files, options.max_open_files};
                ::setrlimit(RLIMIT_NOFILE, &lim);
            }
            ::execve(argv[0], argv.data(), envp.data());
            ::_exit(127);
        }
        ::close(fds[1]);
        DaemonProcess p;
        p.pid_ = pid;
        p.out_ = ::fdopen(fds[0], "r");
        return p;
    }

    DaemonProcess() = default;
    DaemonProcess(DaemonProcess&& o) noexcept : pid_(o.pid_), out_(o.out_), output_(std::move(o.output_)) {
        o.pid_ = -1;
        o.out_ = nullptr;
    }
    DaemonProcess& operator=(DaemonProcess&&) = delete;
    ~DaemonProcess() {
        if (pid_ > 0) {
            ::kill(pid_, SIGKILL);
            ::waitpid(pid_, nullptr, 0);
        }
        if (out_) std::fclose(out_);
    }

    pid_t pid() const { return pid_; }
    bool started() const { return pid_ > 0 && out_; }

    // Reads output lines until one contains `needle` (true) or the output ends (false).
    bool read_until(const std::string& needle) {
        char line[4096];
        while (out_ && std::fgets(line, sizeof line, out_)) {
            output_ += line;
            if (std::string(line).find(needle) != std::string::npos) return true;
        }
        return false;
    }
    // The rest of the output, up to the process's end; then its exit status.
    int wait() {
        read_until("\x01never\x01");
        int status = 0;
        ::waitpid(pid_, &status, 0);
        pid_ = -1;
        return status;
    }
    int terminate() {
        ::kill(pid_, SIGTERM);
        return wait();
    }
    const std::string& output() const { return output_; }

    // User + system CPU time so far, from /proc/<pid>/stat.
    double cpu_seconds() const {
        std::ifstream in("/proc/" + std::to_string(pid_) + "/stat");
        std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        std::istringstream fields(stat.substr(stat.rfind(')') + 2));  // after "(comm) "
        std::string f;
        double ticks = 0;
        for (int i = 3; i <= 15 && fields >> f; ++i)
            if (i == 14 || i == 15) ticks += std::stod(f);  // utime, stime
        return ticks / static_cast<double>(::sysconf(_SC_CLK_TCK));
    }

private:
    pid_t pid_ = -1;
    FILE* out_ = nullptr;
    std::string output_;
};

}  // namespace manikind::test
