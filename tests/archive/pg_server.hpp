#pragma once
// A real PostgreSQL 15 server for one test: a fresh cluster in a temporary folder, listening on a
// Unix socket in that folder only (no TCP), stopped and deleted by the destructor. As root (CI)
// the server runs as nobody: initdb and postgres refuse to run as root.
#include <grp.h>
#include <pwd.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace manikind::test {

class PgServer {
public:
    static constexpr const char* bin_dir = "/usr/lib/postgresql/15/bin";

    static bool available() {
        return std::filesystem::exists(std::string(bin_dir) + "/initdb") &&
               std::filesystem::exists(std::string(bin_dir) + "/pg_ctl");
    }

    PgServer() : port_(15432 + static_cast<int>(getpid() % 1000)) {
        char pattern[] = "/tmp/manikind-pg-XXXXXX";  // short: a socket path must fit in 107 bytes
        if (!mkdtemp(pattern)) throw std::runtime_error("mkdtemp failed");
        dir_ = pattern;
        if (geteuid() == 0) {
            const passwd* nobody = getpwnam("nobody");
            const group* nogroup = getgrnam("nogroup");
            if (!nobody || !nogroup || chown(dir_.c_str(), nobody->pw_uid, nogroup->gr_gid) != 0)
                throw std::runtime_error("cannot hand " + dir_ + " to nobody:nogroup");
            as_user_ = "setpriv --reuid=nobody --regid=nogroup --clear-groups ";
        }
        run(std::string(bin_dir) + "/initdb -D " + dir_ + "/data -U postgres -A trust -E UTF8 --no-sync > " + dir_ +
                "/initdb.log 2>&1",
            "initdb");
        start();
    }
    PgServer(const PgServer&) = delete;
    PgServer& operator=(const PgServer&) = delete;
    ~PgServer() {
        if (running_ && std::system(command("stop -m fast").c_str()) != 0) {
            // Nothing more to do in a destructor: the folder goes below either way.
        }
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }

    // -F: no fsync; a test cluster need not survive a power cut.
    void start() {
        run(command("start -w -t 60 -l " + dir_ + "/server.log -o \"-k " + dir_ + " -c listen_addresses='' -p " +
                    std::to_string(port_) + " -F\""),
            "pg_ctl start");
        running_ = true;
    }
    void stop() {
        run(command("stop -w -m fast"), "pg_ctl stop");
        running_ = false;
    }

    std::string conninfo() const {
        return "host=" + dir_ + " port=" + std::to_string(port_) + " user=postgres dbname=postgres";
    }
    const std::string& dir() const { return dir_; }

private:
    std::string command(const std::string& pg_ctl_args) const {
        return std::string(bin_dir) + "/pg_ctl -D " + dir_ + "/data " + pg_ctl_args + " >> " + dir_ + "/pg_ctl.log 2>&1";
    }
    // From inside the folder: nobody may not be able to enter the test's working directory.
    void run(const std::string& cmd, const char* what) const {
        const std::string full = "cd " + dir_ + " && " + as_user_ + cmd;
        if (std::system(full.c_str()) != 0)
            throw std::runtime_error(std::string(what) + " failed; see the logs in " + dir_ + " (" + full + ")");
    }

    int port_;
    std::string dir_;
    std::string as_user_;
    bool running_ = false;
};

}  // namespace manikind::test
