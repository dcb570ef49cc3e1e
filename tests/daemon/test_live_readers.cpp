// Readers a lab types while the daemon records (issue 60): the plain `sqlite3` shell, Python's
// default sqlite3.connect and pandas' read_sql, each opening the database read-write as such
// tools do and closing it again. Before the fix the daemon itself had opened and closed the
// file outside SQLite at start, which dropped every POSIX lock it held on it; the first reader
// to close then took itself for the last connection, checkpointed and deleted the live -wal,
// and the readings committed after it were gone (46,944 stored by the daemon's count, 16,384 in
// the file). Here: the readers run while a campaign records, the daemon's lock on the file is
// seen from outside (/proc/locks), then SIGTERM and a restart, and every reading the daemon
// counted is in the file.
#include <catch2/catch.hpp>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <fmt/format.h>

#include "daemon/control_client.hpp"
#include "daemon_process.hpp"
#include "store/database.hpp"

namespace fs = std::filesystem;
using manikind::test::DaemonProcess;

namespace {

// Runs a shell command, returns its exit status and what it printed.
std::pair<int, std::string> run(const std::string& command) {
    std::string out;
    FILE* p = ::popen((command + " 2>&1").c_str(), "r");
    if (!p) return {-1, out};
    char buffer[4096];
    while (std::fgets(buffer, sizeof buffer, p)) out += buffer;
    const int status = ::pclose(p);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

bool have(const std::string& command) { return run(command).first == 0; }

// The POSIX (fcntl) locks process `pid` holds on the file `path`, from /proc/locks:
// "1: POSIX  ADVISORY  READ  1234 08:01:5678 1073741824 1073742335".
int posix_locks_on(const fs::path& path, pid_t pid) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return -1;
    std::ifstream in("/proc/locks");
    int n = 0;
    for (std::string line; std::getline(in, line);) {
        std::istringstream f(line);
        std::string id, kind, advisory, mode, holder, device_inode;
        f >> id >> kind;
        if (kind == "->") f >> kind;  // a waiter's line
        f >> advisory >> mode >> holder >> device_inode;
        if (kind != "POSIX" || holder != std::to_string(pid)) continue;
        const auto colon = device_inode.rfind(':');
        if (colon != std::string::npos && device_inode.substr(colon + 1) == std::to_string(st.st_ino)) ++n;
    }
    return n;
}

std::uint64_t committed_now(const fs::path& socket) {
    const auto reply = manikind::call_daemon(socket, {{"cmd", "status"}}, 10.0);
    return reply.at("status").at("recorder").at("committed").get<std::uint64_t>();
}

}  // namespace

TEST_CASE("plain sqlite3 and Python and pandas readers during a campaign lose no reading", "[daemon][readers]") {
    REQUIRE(have("command -v sqlite3"));
    REQUIRE(have("/usr/bin/python3 -c 'import sqlite3'"));
    const bool pandas = have("/usr/bin/python3 -c 'import pandas'");
    if (!pandas) WARN("pandas is not installed: the pandas reader is left out (scripts/setup.sh --tests installs it)");

    const fs::path dir = fs::temp_directory_path() / ("manikind-readers-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    {
        // Long enough that the campaign is still running when the readers are done.
        std::ofstream plan(dir / "plan.toml");
        plan << "name = \"readers\"\nreplicates = 3\ntrial_duration_min = 240\n";
        for (const double air_c : {30.0, 33.0, 36.0})
            plan << "[[cases]]\nchamber_temp_c = " << air_c << "\nchamber_rh_pct = 30\nskin_setpoint_c = 35\nwet = false\n";
        std::ofstream config(dir / "lab.toml");
        config << "[recorder]\ncrash_ring_dir = \"" << dir.string() << "\"\n";
    }
    const fs::path db = dir / "w3.db";
    const fs::path socket = dir / "d.sock";
    const std::vector<std::string> common = {std::string(MANIKIND_BIN_DIR) + "/manikind", "--virtual", "--config",
                                             (dir / "lab.toml").string(), "--database", db.string(), "--socket",
                                             socket.string()};
    auto args = common;
    args.insert(args.end(), {"--campaign", (dir / "plan.toml").string()});
    auto daemon = DaemonProcess::spawn(args);
    REQUIRE(daemon.read_until("acquiring trial 1 "));

    // The daemon holds SQLite's lock on the database file while it records: what tells every
    // other connection that it is not the last one.
    CHECK(posix_locks_on(db, daemon.pid()) > 0);

    const std::string q = "'" + db.string() + "'";
    for (int round = 0; round < 3; ++round) {
        // As a lab types them: the shell read-write (not -readonly), Python's default connect.
        const auto shell = run("sqlite3 " + q + " 'select count(*) from samples'");
        INFO(shell.second);
        CHECK(shell.first == 0);
        const auto python = run("/usr/bin/python3 -c \"import sqlite3,sys; c = sqlite3.connect(sys.argv[1]); "
                                "print(c.execute('select count(*) from samples').fetchone()[0]); c.close()\" " + q);
        INFO(python.second);
        CHECK(python.first == 0);
        if (pandas) {
            const auto frame = run("/usr/bin/python3 -c \"import sqlite3,sys,pandas; c = sqlite3.connect(sys.argv[1]); "
                                   "print(len(pandas.read_sql('select * from samples order by id desc limit 1000', c))); "
                                   "c.close()\" " + q);
            INFO(frame.second);
            CHECK(frame.first == 0);
        }
        // The daemon commits more after each round of readers has closed (a wait on its own
        // count, through its API: what would be lost if a reader had taken the -wal with it).
        const auto before = committed_now(socket);
        while (committed_now(socket) <= before) {
        }
        CHECK(posix_locks_on(db, daemon.pid()) > 0);
        CHECK(fs::exists(db.string() + "-wal"));
    }

    const int status = daemon.terminate();
    const std::string out = daemon.output();
    INFO(out);
    CHECK(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 0);
    CHECK(out.find("lost after their commit") == std::string::npos);
    // "manikind: stopped: A readings accepted, S stored, ...": S is counted in the file.
    const auto at = out.find("readings accepted, ");
    REQUIRE(at != std::string::npos);
    const long long accepted = std::stoll(out.substr(out.rfind(' ', at - 2) + 1));
    const long long stored = std::stoll(out.substr(at + std::string("readings accepted, ").size()));
    CHECK(accepted > 0);
    CHECK(stored == accepted);

    // Restart: it marks nothing lost, and the file holds every reading the first run counted.
    auto restart = common;
    restart.push_back("--exit-when-done");
    auto again = DaemonProcess::spawn(restart);
    CHECK(WEXITSTATUS(again.wait()) == 0);
    auto file = manikind::recorder::Database::open_read_only(db);
    CHECK(file.integrity_check() == "ok");
    const long long in_file = file.rows_since({});
    CHECK(in_file >= stored);
    const auto campaigns = file.campaigns();
    REQUIRE(campaigns.size() == 1);
    CHECK(campaigns[0].state == "interrupted");  // the end state the daemon wrote at SIGTERM is there
    const auto trials = file.trials(campaigns[0].id);
    REQUIRE(!trials.empty());
    CHECK(trials.back().state == "interrupted");
    CHECK(trials.back().reason == "daemon stopped");
    fs::remove_all(dir);
}
