#include <catch2/catch.hpp>

#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "protocol/windsonic.hpp"

using namespace manikind::protocol::windsonic;

namespace {

// The manual's example lines (tests/data/devices/windsonic_manual_examples.txt) with <STX>
// and <ETX> written out; returns the raw frames with CR LF.
std::vector<std::string> manual_frames() {
    std::ifstream in(std::string(MANIKIND_TEST_DATA_DIR) + "/devices/windsonic_manual_examples.txt");
    std::vector<std::string> frames;
    std::string line;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#') continue;
        for (const auto& [token, byte] : {std::pair<std::string, char>{"<STX>", '\x02'}, {"<ETX>", '\x03'}}) {
            const auto at = line.find(token);
            if (at != std::string::npos) line.replace(at, token.size(), std::string(1, byte));
        }
        frames.push_back(line + "\r\n");
    }
    return frames;
}

std::vector<Reading> feed_all(Parser& p, const std::string& bytes) {
    std::vector<Reading> out;
    for (unsigned char c : bytes)
        if (p.feed(c) == Parser::Event::reading) out.push_back(p.reading());
    return out;
}

}  // namespace

TEST_CASE("WindSonic manual section 9.1: Q,229,002.74,M,00 with checksum 16 decodes", "[protocol][windsonic]") {
    const auto frames = manual_frames();
    REQUIRE(frames.size() == 1);
    Parser p;
    const auto readings = feed_all(p, frames[0]);
    REQUIRE(readings.size() == 1);
    const Reading& r = readings[0];
    CHECK(r.node == 'Q');
    REQUIRE(r.direction_deg.has_value());
    CHECK(*r.direction_deg == 229);
    CHECK(r.speed == Approx(2.74));
    CHECK(r.units == 'M');
    CHECK(r.status == 0);
    CHECK(status_ok(r.status));
    CHECK(p.counters().checksum_errors == 0);
    // and our encoder writes the manual's bytes exactly
    CHECK(encode_frame(r) == frames[0]);
    CHECK(checksum("Q,229,002.74,M,00,") == 0x16);
}

TEST_CASE("WindSonic: the manual's spaced rendering 'Q, 229, 002.74, M, 00,' parses the same", "[protocol][windsonic]") {
    const auto r = parse_payload("Q, 229, 002.74, M, 00,");
    REQUIRE(r.has_value());
    CHECK(*r->direction_deg == 229);
    CHECK(r->speed == Approx(2.74));
}

TEST_CASE("WindSonic: round trips polar and UV, knots convert to m/s, status codes name their fault", "[protocol][windsonic]") {
    Reading polar;
    polar.node = 'A';
    polar.direction_deg = 7;
    polar.speed = 12.5;
    polar.units = 'N';
    polar.status = 4;
    Parser p;
    auto out = feed_all(p, encode_frame(polar));
    REQUIRE(out.size() == 1);
    CHECK(*out[0].direction_deg == 7);
    CHECK(out[0].speed_m_s() == Approx(12.5 * 0.514444));
    CHECK(std::string(status_text(out[0].status)) == "axis 1 and 2 failed");
    Reading uv;
    uv.format = Format::uv;
    uv.u = -1.25;
    uv.v = 0.5;
    out = feed_all(p, encode_frame(uv));
    REQUIRE(out.size() == 1);
    CHECK(out[0].format == Format::uv);
    CHECK(out[0].u == Approx(-1.25));
    CHECK(out[0].v == Approx(0.5));
    Reading calm;
    calm.speed = 0.0;  // no direction below the threshold: empty field
    out = feed_all(p, encode_frame(calm));
    REQUIRE(out.size() == 1);
    CHECK_FALSE(out[0].direction_deg.has_value());
    CHECK(std::string(status_text(0x51)) == "measurement average building");
}

TEST_CASE("WindSonic parser: byte-at-a-time across partial reads, garbage and a bad checksum", "[protocol][windsonic]") {
    const std::string good = manual_frames().at(0);
    std::string bad = good;
    bad[bad.size() - 3] = '7';  // checksum "17" instead of "16"
    const std::string stream = "\xff\x13garbage" + good.substr(0, 7) + good + bad + "\x02Q,2" + good;
    Parser p;
    const auto readings = feed_all(p, stream);
    CHECK(readings.size() == 2);  // the cut-off frame and the bad checksum are dropped
    CHECK(p.counters().checksum_errors == 1);
    CHECK(p.counters().frames == 2);
    CHECK(p.counters().bytes_discarded > 0);
}

TEST_CASE("WindSonic parser: seeded random input never crashes and never yields an unchecked frame", "[protocol][windsonic][fuzz]") {
    std::mt19937 rng(20261122);
    std::uniform_int_distribution<int> byte(0, 255);
    Parser p;
    std::uint64_t readings = 0;
    for (int i = 0; i < 200000; ++i) {
        // Mostly noise, sometimes framing bytes and digits, so the parser's states get exercised.
        int b = byte(rng);
        if (b < 20) b = 0x02;
        else if (b < 30) b = 0x03;
        if (p.feed(static_cast<std::uint8_t>(b)) == Parser::Event::reading) {
            ++readings;
            CHECK(p.reading().status >= 0);
        }
    }
    CHECK(p.counters().frames == readings);
    // and a valid frame after all that noise still decodes
    CHECK(feed_all(p, manual_frames().at(0)).size() == 1);
}
