#include <catch2/catch.hpp>

#include "drivers/register_map.hpp"
#include "base/user_error.hpp"

using namespace manikind;

TEST_CASE("register map: the shipped Eurotherm 3200 map loads, PV is address 1, target setpoint 2 (HA028651 15.5)", "[register_map]") {
    const auto map = load_register_map(std::string(MANIKIND_CONFIG_DIR) + "/chamber_registers.toml");
    CHECK(map.family == "Eurotherm 3200 series");
    const auto& pv = map.at("air_temp_pv_c");
    CHECK(pv.unit_id == 1);
    CHECK(pv.spec.address == 1);
    CHECK_FALSE(pv.spec.writable);
    const auto& sp = map.at("air_temp_target_setpoint_c");
    CHECK(sp.spec.address == 2);
    // A 41.0 C setpoint goes out as the x10 integer 410; 60 C is refused before it is sent.
    CHECK(protocol::modbus_registers::encode(sp.spec, 41.0) == std::vector<std::uint16_t>{410});
    CHECK_THROWS_WITH(protocol::modbus_registers::encode(sp.spec, 60.0), Catch::Contains("outside the limits"));
    CHECK(map.at("air_rh_pv_pct").unit_id == 2);
    CHECK_THROWS_AS(map.at("nonexistent"), UserError);
}

TEST_CASE("register map: bad entries name the file, line and key", "[register_map]") {
    const std::string head = "family = \"x\"\n[units]\nt = 1\n";
    CHECK_THROWS_WITH(parse_register_map(head + "[[registers]]\nname = \"a\"\nunit_id = \"t\"\naddress = 1\ntype = \"int24\"\naccess = \"read\"\n", "m.toml"),
                      Catch::Contains("m.toml:4:") && Catch::Contains("int24"));
    CHECK_THROWS_WITH(parse_register_map(head + "[[registers]]\nname = \"a\"\nunit_id = \"h\"\naddress = 1\ntype = \"int16\"\naccess = \"read\"\n", "m.toml"),
                      Catch::Contains("not in [units]"));
    CHECK_THROWS_WITH(parse_register_map(head + "[[registers]]\nname = \"a\"\nunit_id = \"t\"\naddress = 1\ntype = \"int16\"\naccess = \"read_write\"\n", "m.toml"),
                      Catch::Contains("needs min and max"));
    CHECK_THROWS_WITH(parse_register_map(head + "[[registers]]\nname = \"a\"\nunit_id = \"t\"\naddress = 70000\ntype = \"int16\"\naccess = \"read\"\n", "m.toml"),
                      Catch::Contains("0..65535"));
}
