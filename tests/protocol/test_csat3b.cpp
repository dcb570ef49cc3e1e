#include <catch2/catch.hpp>

#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "protocol/csat3b.hpp"

using namespace manikind::protocol::csat3b;

namespace {

// The manual's example lines (tests/data/devices/csat3b_manual_examples.txt), no terminator.
std::vector<std::string> manual_lines() {
    std::ifstream in(MANIKIND_TEST_DATA_DIR "/devices/csat3b_manual_examples.txt");
    std::vector<std::string> lines;
    std::string line;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#') continue;
        lines.push_back(line);
    }
    return lines;
}

std::vector<Record> feed_all(Parser& p, const std::string& bytes) {
    std::vector<Record> out;
    for (unsigned char c : bytes)
        if (p.feed(c) == Parser::Event::record) out.push_back(p.record());
    return out;
}

std::string lower(std::string s) {
    for (char& c : s)
        if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
    return s;
}

}  // namespace

TEST_CASE("CSAT3B manual 8.3.3 p. 55: all 12 example lines parse and their signatures verify", "[protocol][csat3b]") {
    const auto lines = manual_lines();
    REQUIRE(lines.size() == 12);
    int expected_counter = 5;
    for (const auto& line : lines) {
        INFO(line);
        std::string why;
        const auto r = parse_line(line, &why);
        INFO(why);
        REQUIRE(r.has_value());
        CHECK(r->counter == expected_counter++);
        CHECK(r->diag == 0);
        CHECK(signature(signed_part(line)) == r->signature);
    }
    // the last example prints its signature as "5cD7": hex is read in any case
    CHECK(parse_line(lines.back())->signature == 0x5cd7);
}

TEST_CASE("CSAT3B: the signature covers Ux..DiagWord, not the record counter the manual's prose names", "[protocol][csat3b]") {
    const std::string line = "0.08945,0.06552,0.05726,19.69336,0,5,c3a6";
    CHECK(signed_part(line) == "0.08945,0.06552,0.05726,19.69336,0");
    CHECK(signature("0.08945,0.06552,0.05726,19.69336,0") == 0xc3a6);
    CHECK(signature("0.08945,0.06552,0.05726,19.69336,0,5") != 0xc3a6);
    CHECK(signature("0.08945,0.06552,0.05726,19.69336,0,") != 0xc3a6);
    CHECK(signed_part("1,2,3,4") == "");
}

TEST_CASE("CSAT3B: the first manual line's values exactly", "[protocol][csat3b]") {
    const auto r = parse_line(manual_lines().at(0));
    REQUIRE(r.has_value());
    CHECK(r->ux_m_s == 0.08945);
    CHECK(r->uy_m_s == 0.06552);
    CHECK(r->uz_m_s == 0.05726);
    CHECK(r->sonic_temp_c == 19.69336);
    CHECK(r->diag == 0);
    CHECK(r->diag_ok());
    CHECK(r->counter == 5);
    CHECK(r->signature == 0xc3a6);
    CHECK(r->horizontal_speed_m_s() == Approx(std::hypot(0.08945, 0.06552)));
    CHECK(r->speed_m_s() == Approx(std::sqrt(0.08945 * 0.08945 + 0.06552 * 0.06552 + 0.05726 * 0.05726)));
}

TEST_CASE("CSAT3B: encode_line of a parsed manual line gives the same bytes and signature", "[protocol][csat3b]") {
    for (const auto& line : manual_lines()) {
        INFO(line);
        const auto r = parse_line(line);
        REQUIRE(r.has_value());
        const std::string encoded = encode_line(*r);
        CHECK(encoded == lower(line) + "\r\n");  // lower-case hex on output
        const auto back = parse_line(encoded);
        REQUIRE(back.has_value());
        CHECK(back->ux_m_s == r->ux_m_s);
        CHECK(back->uy_m_s == r->uy_m_s);
        CHECK(back->uz_m_s == r->uz_m_s);
        CHECK(back->sonic_temp_c == r->sonic_temp_c);
        CHECK(back->diag == r->diag);
        CHECK(back->counter == r->counter);
        CHECK(back->signature == r->signature);
    }
}

TEST_CASE("CSAT3B: encode_line signs negative values and a diagnostic word, wraps the counter mod 64", "[protocol][csat3b]") {
    Record r;
    r.ux_m_s = -1.25;
    r.uy_m_s = 3.5;
    r.uz_m_s = -0.00001;
    r.sonic_temp_c = -12.34567;
    r.diag = acquiring | low_voltage;
    r.counter = 65;
    const std::string line = encode_line(r);
    CHECK(line.substr(0, line.rfind(',') + 1) == "-1.25000,3.50000,-0.00001,-12.34567,48,1,");
    const auto back = parse_line(line);
    REQUIRE(back.has_value());
    CHECK(back->counter == 1);
    CHECK(back->diag == 48);
    CHECK(back->ux_m_s == -1.25);
}

TEST_CASE("CSAT3B: a flipped digit gives a signature error, bad fields are malformed", "[protocol][csat3b]") {
    const std::string good = manual_lines().at(0);
    std::string flipped = good;
    flipped[3] = '5';  // 0.08945 -> 0.08545
    std::string why;
    CHECK_FALSE(parse_line(flipped, &why).has_value());
    CHECK(why == "signature mismatch");

    Parser p;
    CHECK(feed_all(p, flipped + "\r").empty());
    CHECK(p.counters().signature_errors == 1);
    CHECK(p.counters().malformed == 0);

    CHECK_FALSE(parse_line("0.08945,0.06552,0.05726,19.69336,0,64,c3a6", &why).has_value());
    CHECK(why == "record counter is not 0..63");
    CHECK_FALSE(parse_line("0.08945,0.06552,0.05726,19.69336,0,5,c3a", &why).has_value());
    CHECK(why == "signature is not 4 hex digits");
    CHECK_FALSE(parse_line("0.08945,0.06552,0.05726,19.69336,0,5", &why).has_value());
    CHECK(why == "fewer than 7 fields");
    CHECK_FALSE(parse_line("0.08945,0.06552,0.05726,19.69336,0,5,c3a6,", &why).has_value());
    CHECK(why == "more than 7 fields");
    CHECK_FALSE(parse_line("0.08945,x,0.05726,19.69336,0,5,c3a6", &why).has_value());
    CHECK(why == "Ux, Uy, Uz or Ts is not a number");
    CHECK_FALSE(parse_line("inf,0.06552,0.05726,19.69336,0,5,c3a6").has_value());
    CHECK_FALSE(parse_line("0.08945,0.06552,0.05726,19.69336,-1,5,c3a6").has_value());
}

TEST_CASE("CSAT3B: NaN values parse as quiet NaN when the signature matches", "[protocol][csat3b]") {
    Record nan_record;
    nan_record.ux_m_s = nan_record.uy_m_s = nan_record.uz_m_s = nan_record.sonic_temp_c = std::nan("");
    nan_record.diag = acquiring;
    nan_record.counter = 3;
    const std::string line = encode_line(nan_record);
    CHECK(line.substr(0, line.rfind(',') + 1) == "NaN,NaN,NaN,NaN,16,3,");
    const auto r = parse_line(line);
    REQUIRE(r.has_value());
    CHECK(std::isnan(r->ux_m_s));
    CHECK(std::isnan(r->sonic_temp_c));
    CHECK(diag_text(r->diag) == "acquiring");
    std::string bad = line;
    char& digit = bad[bad.size() - 3];  // a signature digit (before CR LF)
    digit = digit == '0' ? '1' : '0';
    CHECK_FALSE(parse_line(bad).has_value());
}

TEST_CASE("CSAT3B manual 8.4.2 Table 8-5: diagnostic word text", "[protocol][csat3b]") {
    CHECK(diag_text(0) == "ok");
    CHECK(diag_text(0x10) == "acquiring");
    CHECK(diag_text(0x21) == "low_amplitude,low_voltage");
    CHECK(diag_text(0x1FF) ==
          "low_amplitude,high_amplitude,tracking,high_delta_c,acquiring,low_voltage,trigger_error,"
          "internal_humidity,memory_error");
    CHECK(diag_text(0x204) == "tracking,unknown_bits_0x200");
}

TEST_CASE("CSAT3B parser: the whole manual file byte by byte gives 12 records, no errors, no gaps", "[protocol][csat3b]") {
    std::ifstream in(MANIKIND_TEST_DATA_DIR "/devices/csat3b_manual_examples.txt", std::ios::binary);
    const std::string file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    REQUIRE_FALSE(file.empty());
    // The '#' header lines are malformed records to the parser: strip them, keep the bytes
    // (LF terminators) of the rest as they are in the file.
    std::string body;
    for (const auto& line : manual_lines()) body += line + "\n";
    Parser p;
    const auto records = feed_all(p, body);
    REQUIRE(records.size() == 12);
    CHECK(records.front().counter == 5);
    CHECK(records.back().counter == 16);
    CHECK(p.counters().records == 12);
    CHECK(p.counters().signature_errors == 0);
    CHECK(p.counters().malformed == 0);
    CHECK(p.counters().counter_gaps == 0);
    CHECK(p.counters().bytes_discarded == 0);
    // and the file as it is: 4 header lines are malformed, the 12 records still come through
    Parser raw;
    CHECK(feed_all(raw, file).size() == 12);
    CHECK(raw.counters().malformed == 4);
}

TEST_CASE("CSAT3B parser: CR, LF and CR LF terminators, counter gaps and the 63 -> 0 wrap", "[protocol][csat3b]") {
    const auto lines = manual_lines();
    Parser p;
    const std::string stream = lines[0] + "\r" + lines[1] + "\n" + lines[2] + "\r\n" + lines[4] + "\r\n";  // line 3 lost
    CHECK(feed_all(p, stream).size() == 4);
    CHECK(p.counters().counter_gaps == 1);
    Record r;
    r.counter = 63;
    std::string wrap = encode_line(r);
    r.counter = 64;
    wrap += encode_line(r);
    Parser q;
    CHECK(feed_all(q, wrap).size() == 2);
    CHECK(q.counters().counter_gaps == 0);
}

TEST_CASE("CSAT3B parser: garbage prefix and a truncated first line, then resync", "[protocol][csat3b]") {
    const auto lines = manual_lines();
    std::string stream("\xff\x13\x00garbage", 10);
    stream += lines[0].substr(12) + "\r";        // binary noise, then the tail of a line
    stream += lines[1].substr(20) + "\r\n";      // printable tail of a line: malformed
    for (std::size_t i = 2; i < 6; ++i) stream += lines[i] + "\r";
    Parser p;
    const auto records = feed_all(p, stream);
    REQUIRE(records.size() == 4);
    CHECK(records.front().counter == 7);
    CHECK(p.counters().malformed == 2);
    CHECK(p.counters().signature_errors == 0);
    CHECK(p.counters().bytes_discarded == 10 + (lines[0].size() - 12) + (lines[1].size() - 20));
    CHECK(p.counters().counter_gaps == 0);
}

TEST_CASE("CSAT3B parser: an overlong line is malformed once and the next line decodes", "[protocol][csat3b]") {
    Parser p;
    const std::string stream = std::string(300, '1') + "\r" + manual_lines().at(0) + "\r";
    CHECK(feed_all(p, stream).size() == 1);
    CHECK(p.counters().malformed == 1);
    CHECK(p.counters().bytes_discarded == 300);
}

TEST_CASE("CSAT3B parser: seeded random input and mutated lines never crash, counters stay consistent", "[protocol][csat3b][fuzz]") {
    const auto lines = manual_lines();
    std::mt19937 rng(20261123);
    std::uniform_int_distribution<int> byte(0, 255);
    std::uniform_int_distribution<std::size_t> pick(0, lines.size() - 1);
    const std::string alphabet = "0123456789,.-NaN\r\nabcdef";
    std::uniform_int_distribution<std::size_t> letter(0, alphabet.size() - 1);
    Parser p;
    std::uint64_t terminators = 0, records = 0, events = 0;
    auto feed = [&](std::uint8_t b) {
        if (b == '\r' || b == '\n') ++terminators;
        const auto e = p.feed(b);
        if (e != Parser::Event::none) ++events;
        if (e == Parser::Event::record) {
            ++records;
            CHECK(p.record().counter >= 0);
            CHECK(p.record().counter <= 63);
        }
    };
    for (int i = 0; i < 200000; ++i) {
        // Mostly noise biased towards the record alphabet, every 1000 bytes a mutated valid line.
        const int b = byte(rng);
        feed(static_cast<std::uint8_t>(b < 128 ? alphabet[letter(rng)] : b));
        if (i % 1000 == 0) {
            std::string line = "\r" + lines[pick(rng)] + "\r\n";
            if (i % 2000 == 0) line[std::uniform_int_distribution<std::size_t>(1, line.size() - 3)(rng)] = alphabet[letter(rng)];
            for (unsigned char c : line) feed(c);
        }
    }
    const auto& c = p.counters();
    CHECK(c.records == records);
    CHECK(c.records + c.signature_errors + c.malformed == events);
    CHECK(events <= terminators + 1);
    CHECK(records >= 100);  // the unmutated lines at least (noise may cut into one before it)
    // and a valid line after all that noise still decodes
    CHECK(feed_all(p, "\r" + lines[0] + "\r").size() == 1);
}
