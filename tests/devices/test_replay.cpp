// A candump -l file written by hand from the documented frame layout replays into the same zone
// values that the same frames give live on the bus (issue 9).
#include <catch2/catch.hpp>

#include <sys/socket.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include "drivers/manikin_can_driver.hpp"

using namespace manikind;

namespace {

std::map<std::string, drivers::Sample> replay(const std::string& file, std::vector<can_frame>& frames) {
    drivers::ManualClock clock(0);
    boost::asio::io_context io;
    std::map<std::string, drivers::Sample> last;
    drivers::ManikinCanDriver driver(io, -1, {}, clock, [&](const drivers::Sample& s) { last[s.channel] = s; });
    std::ifstream in(file);
    std::string line;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#') continue;
        const auto parsed = protocol::manikin_can::parse_candump_line(line);
        REQUIRE(parsed);
        frames.push_back(parsed->second);
        driver.ingest(parsed->second);
    }
    CHECK(driver.status().malformed == 0);
    return last;
}

}  // namespace

TEST_CASE("a hand-written candump -l capture replays into the documented zone values", "[devices][replay]") {
    std::vector<can_frame> frames;
    const auto last = replay(MANIKIND_TEST_DATA_DIR "/devices/manikin_capture.log", frames);
    REQUIRE(frames.size() == 3);
    CHECK(last.at("z05.skin_temp_c").value == Approx(35.01));
    CHECK(last.at("z05.heat_flux_w_m2").value == Approx(84.6));
    CHECK(last.at("z05.sweat_rate_g_m2_h").value == Approx(150.0));
    CHECK(last.at("z23.skin_temp_c").value == Approx(34.87));
    CHECK(last.at("z23.heat_flux_w_m2").value == Approx(-12.5));
    CHECK(last.at("z23.skin_temp_c").quality == drivers::Quality::out_of_range);  // sensor fault bit
    CHECK(last.at("z05.skin_temp_c").quality == drivers::Quality::good);
}

TEST_CASE("the same frames live on a socketpair bus give the same values as the replay", "[devices][replay]") {
    std::vector<can_frame> frames;
    const auto replayed = replay(MANIKIND_TEST_DATA_DIR "/devices/manikin_capture.log", frames);
    int sv[2];
    REQUIRE(::socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) == 0);
    drivers::ManualClock clock;
    boost::asio::io_context io;
    std::map<std::string, drivers::Sample> live;
    drivers::ManikinCanDriver driver(io, sv[1], {}, clock, [&](const drivers::Sample& s) { live[s.channel] = s; });
    driver.start();
    for (const auto& f : frames) REQUIRE(::send(sv[0], &f, sizeof f, 0) == static_cast<ssize_t>(sizeof f));
    while (driver.frames_received() < frames.size()) io.run_one();
    REQUIRE(live.size() == replayed.size());
    for (const auto& [channel, s] : replayed) {
        INFO(channel);
        CHECK(live.at(channel).value == s.value);
        CHECK(live.at(channel).quality == s.quality);
    }
    ::close(sv[0]);
}

TEST_CASE("the driver's capture is a candump -l log that replays to the same values", "[devices][replay]") {
    const std::string path = (std::filesystem::temp_directory_path() / ("manikind-capture-" + std::to_string(::getpid()) + ".log")).string();
    std::vector<can_frame> frames;
    const auto replayed = replay(MANIKIND_TEST_DATA_DIR "/devices/manikin_capture.log", frames);
    {
        drivers::ManualClock clock;
        boost::asio::io_context io;
        drivers::ManikinCanDriver driver(io, -1, {}, clock, [](const drivers::Sample&) {});
        driver.capture_to(path);
        for (const auto& f : frames) driver.ingest(f);
    }
    std::vector<can_frame> again;
    const auto from_capture = replay(path, again);
    CHECK(again.size() == frames.size());
    for (const auto& [channel, s] : replayed) CHECK(from_capture.at(channel).value == s.value);
    std::filesystem::remove(path);
}
