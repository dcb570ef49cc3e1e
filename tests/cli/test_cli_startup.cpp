// Start-up (issue 36): HDF5, libpq, libcurl and libcrypto are loaded by the commands that use them,
// through the modules beside the program (base/lazy_library.hpp), never at start. Checked on the
// built programs: what the dynamic loader is told to load, and what a program whose modules are
// missing does (the quick commands run; an HDF5 export says what is missing and writes nothing).
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <string>

#include "run_cli.hpp"

namespace fs = std::filesystem;
using manikind::test::CliResult;

namespace {

CliResult run(const std::string& command) {
    CliResult r;
    FILE* pipe = popen((command + " 2>&1").c_str(), "r");
    if (!pipe) return r;
    char buf[4096];
    std::size_t n = 0;
    while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) r.out.append(buf, n);
    const int status = pclose(pipe);
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

struct StartupDir {
    fs::path path = fs::temp_directory_path() / ("manikind-startup-" + std::to_string(::getpid()));
    StartupDir() { fs::remove_all(path); fs::create_directories(path); }
    ~StartupDir() { fs::remove_all(path); }
};

}  // namespace

TEST_CASE("start-up: neither program asks the loader for HDF5, libpq, libcurl or libcrypto: their modules do",
          "[cli][startup]") {
    const std::string bin = MANIKIND_BIN_DIR;
    for (const char* program : {"manikin", "manikind"}) {
        const auto needed = run("readelf -d " + bin + "/" + program);
        REQUIRE(needed.exit_code == 0);
        INFO(program << ":\n" << needed.out);
        CHECK(needed.out.find("libmodbus") != std::string::npos);  // the reading worked: a library it does link
        for (const char* lazy : {"libhdf5", "libpq", "libcurl", "libcrypto", "libssl"}) CHECK(needed.out.find(lazy) == std::string::npos);
    }
    const std::pair<const char*, const char*> modules[] = {{"libmanikind-hdf5.so", "libhdf5"},
                                                           {"libmanikind-pq.so", "libpq"},
                                                           {"libmanikind-curl.so", "libcurl"},
                                                           {"libmanikind-crypto.so", "libcrypto"}};
    for (const auto& [module, library] : modules) {
        const auto needed = run("readelf -d " + bin + "/" + module);
        INFO(module << ":\n" << needed.out);
        REQUIRE(needed.exit_code == 0);
        CHECK(needed.out.find(std::string("Shared library: [") + library) != std::string::npos);
    }
}

TEST_CASE("start-up: without its modules the program still answers --version and --help, and an HDF5 export "
          "names what is missing, exits 2 and writes nothing",
          "[cli][startup]") {
    StartupDir dir;
    const fs::path lone = dir.path / "manikin";
    fs::copy_file(fs::path(MANIKIND_BIN_DIR) / "manikin", lone);  // no modules beside this copy
    const auto version = run(lone.string() + " --version");
    CHECK(version.exit_code == 0);
    CHECK(version.out.find("manikin ") != std::string::npos);
    CHECK(run(lone.string() + " export --help").exit_code == 0);

    // A database to export: the demo's, recorded by the real program (with its modules).
    const auto demo = manikind::test::run_manikin("demo --cases 1 --replicates 1 --out " + (dir.path / "lab").string() + " > /dev/null");
    REQUIRE(demo.exit_code == 0);
    const auto list = run(lone.string() + " campaigns --db " + (dir.path / "lab" / "manikind.db").string() + " --json");
    REQUIRE(list.exit_code == 0);  // reading the database needs no module
    const auto name_at = list.out.find("\"name\": \"");
    REQUIRE(name_at != std::string::npos);
    const auto start = name_at + 9;
    const std::string campaign = list.out.substr(start, list.out.find('"', start) - start);

    const fs::path out = dir.path / "out.h5";
    const auto h5 = run(lone.string() + " export --db " + (dir.path / "lab" / "manikind.db").string() + " " + campaign + " " + out.string());
    INFO(h5.out);
    CHECK(h5.exit_code == 2);
    CHECK(h5.out.find("HDF5 (libhdf5, for HDF5 exports) is needed here and could not be loaded") != std::string::npos);
    CHECK(h5.out.find((dir.path / "libmanikind-hdf5.so").string() + ": not there") != std::string::npos);
    CHECK_FALSE(fs::exists(out));
    // The CSV export needs none of them.
    CHECK(run(lone.string() + " export --db " + (dir.path / "lab" / "manikind.db").string() + " " + campaign + " " +
              (dir.path / "csv").string())
              .exit_code == 0);
    CHECK(fs::exists(dir.path / "csv" / "campaign.json"));
}
