// Block reads (issue 18): which registers go in one Modbus request.
#include <catch2/catch.hpp>

#include <vector>

#include "protocol/modbus_blocks.hpp"

using namespace manikind::protocol::modbus_blocks;

TEST_CASE("contiguous registers of one unit and function are one request, in address order", "[protocol][modbus]") {
    // The shipped datalogger's layout: two probes (T, RH) at 0..3, four thermocouples at 16..19.
    const std::vector<PointRegisters> pts = {{1, false, 1, 1}, {1, false, 0, 1}, {1, false, 3, 1}, {1, false, 2, 1},
                                             {1, false, 16, 1}, {1, false, 17, 1}, {1, false, 18, 1}, {1, false, 19, 1}};
    const auto blocks = plan_read_blocks(pts);
    REQUIRE(blocks.size() == 2);  // a hole at 4..15 splits them (a device may refuse unmapped registers)
    CHECK(blocks[0].start == 0);
    CHECK(blocks[0].count == 4);
    CHECK(blocks[0].points == std::vector<std::size_t>{1, 0, 3, 2});
    CHECK(blocks[1].start == 16);
    CHECK(blocks[1].count == 4);
    // Allowing a gap of 12 registers reads all eight in one request of 20.
    const auto bridged = plan_read_blocks(pts, kMaxReadRegisters, 12);
    REQUIRE(bridged.size() == 1);
    CHECK(bridged[0].count == 20);
}

TEST_CASE("units, functions, two-register types and the 125-register limit split requests", "[protocol][modbus]") {
    // float32 at 10 (10, 11) then int16 at 12: contiguous. Unit 2 and FC 04 are separate requests.
    const std::vector<PointRegisters> pts = {{1, false, 10, 2}, {1, false, 12, 1}, {2, false, 13, 1}, {1, true, 13, 1}};
    const auto blocks = plan_read_blocks(pts);
    REQUIRE(blocks.size() == 3);
    CHECK((blocks[0].unit_id == 1 && !blocks[0].input_register && blocks[0].start == 10 && blocks[0].count == 3));
    CHECK((blocks[1].unit_id == 1 && blocks[1].input_register && blocks[1].start == 13 && blocks[1].count == 1));
    CHECK((blocks[2].unit_id == 2 && blocks[2].start == 13));
    // 130 consecutive int16 registers: 125 (the protocol's maximum for FC 03, §6.3) + 5.
    std::vector<PointRegisters> many;
    for (int a = 0; a < 130; ++a) many.push_back({1, false, a, 1});
    const auto split = plan_read_blocks(many);
    REQUIRE(split.size() == 2);
    CHECK(split[0].count == 125);
    CHECK(split[1].start == 125);
    CHECK(split[1].count == 5);
    // Two points on the same register (a raw and a scaled view): one register read once.
    const std::vector<PointRegisters> same = {{1, false, 5, 1}, {1, false, 5, 1}};
    const auto one = plan_read_blocks(same);
    REQUIRE(one.size() == 1);
    CHECK(one[0].count == 1);
    CHECK(one[0].points.size() == 2);
    CHECK(plan_read_blocks(std::vector<PointRegisters>{}).empty());
    // max_registers 0: one request per point, a float32 too, in address order (the driver's
    // fallback for a device that refuses multi-register reads).
    const auto singles = plan_read_blocks(pts, 0, 0);
    REQUIRE(singles.size() == 4);
    CHECK((singles[0].start == 10 && singles[0].count == 2 && singles[0].points == std::vector<std::size_t>{0}));
    CHECK((singles[1].start == 12 && singles[1].count == 1 && singles[1].points == std::vector<std::size_t>{1}));
    CHECK(plan_read_blocks(same, 0, 0).size() == 2);
}
