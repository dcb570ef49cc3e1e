// The simulated anemometers' polled mode: a node letter from the host asks for a frame at once.
// The simulated lab learns what the host sent from one poll over its lines per step, not a read
// on each (sim/lab/sim_lab.cpp, SimLab::step).
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <string>

#include "analysis/zone_map.hpp"
#include "sim/lab/sim_lab.hpp"

namespace {

struct TempRuntime {
    std::filesystem::path dir;
    TempRuntime() {
        static std::atomic<int> serial{0};
        dir = std::filesystem::temp_directory_path() / ("manikind-test-poll-" + std::to_string(::getpid()) + "-" + std::to_string(serial++));
    }
    ~TempRuntime() {
        std::error_code ec;
        std::filesystem::remove_all(dir, ec);
    }
};

}  // namespace

TEST_CASE("simulated anemometers: a node letter from the host gets a frame at once, between their periodic frames", "[devices]") {
    TempRuntime runtime;
    manikind::sim::SimLabOptions o;
    o.runtime_dir = runtime.dir;
    for (const auto& z : manikind::analysis::andi35_zone_map().zones)
        o.world.zones.push_back({{z.zone, z.segment, z.region, z.area_m2, 35.0}, z.name});
    o.windsonic_period_s = 100.0;  // periodic frames far apart: what comes between was asked for
    o.csat3b_period_s = 100.0;
    manikind::sim::SimLab lab(o);
    const auto ends = lab.endpoints();
    const int host = ::open(ends.windsonic_pty.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
    REQUIRE(host >= 0);
    lab.step(1.0);  // the first periodic frame
    char drain[512];
    while (::read(host, drain, sizeof drain) > 0) {
    }
    lab.step(1.0);
    CHECK(lab.serial_bytes_last_step("windsonic") == 0);
    CHECK(lab.serial_bytes_last_step("csat3b") == 0);

    REQUIRE(::write(host, "Q", 1) == 1);  // polled mode: the node letter
    lab.step(1.0);
    CHECK(lab.serial_bytes_last_step("windsonic") > 0);
    CHECK(lab.serial_bytes_last_step("csat3b") == 0);  // asked nothing: says nothing
    lab.step(1.0);
    CHECK(lab.serial_bytes_last_step("windsonic") == 0);  // one letter, one frame
    ::close(host);
}
