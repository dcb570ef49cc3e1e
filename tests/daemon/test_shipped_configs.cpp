// The files shipped in config/ load, and bad ones fail with the file, line and key named.
#include <catch2/catch.hpp>

#include "daemon/core/campaign_plan.hpp"
#include "daemon/core/config.hpp"
#include "daemon/core/register_map.hpp"
#include "daemon/core/user_error.hpp"

using namespace manikind;

TEST_CASE("the shipped real-lab config, register maps and campaign example load", "[daemon][config]") {
    const auto c = config::load_config(MANIKIND_CONFIG_DIR "/real-lab.toml");
    CHECK(c.warnings.empty());
    CHECK(c.mode == "real");
    CHECK(c.devices.chamber.host == "192.168.10.20");
    CHECK(c.devices.manikin_interface == "can0");
    CHECK(c.api.token.size() > 8);
    const auto chamber = register_map_from_setting(c.devices.chamber.register_map, "chamber", c.source_dir);
    CHECK(chamber.at("air_temp_remote_setpoint_c").spec.writable);
    const auto logger = register_map_from_setting(c.devices.datalogger.register_map, "datalogger", c.source_dir);
    REQUIRE(logger.at("ee181_1.air_temp_c").probe);
    // EE181 0-1 V output, -40..60 °C: 620 mV is 22 °C.
    CHECK(logger.at("ee181_1.air_temp_c").probe->to_value(620.0) == Approx(22.0));
    const auto plan = load_campaign_plan(MANIKIND_CONFIG_DIR "/campaign-example.toml");
    CHECK(plan.cases.size() == 2);
    CHECK(plan.replicates == 3);
    CHECK(check_plan_against_limits(plan, c.safety).empty());
    CHECK(load_campaign_plan("builtin:table-s3").cases.size() == 15);
}

TEST_CASE("bad device and campaign settings name the file, line and key", "[daemon][config]") {
    CHECK_THROWS_WITH(config::parse_config("[devices.chamber]\nport = \"502\"\n", "lab.toml"),
                      Catch::Contains("lab.toml:2") && Catch::Contains("devices.chamber.port: expected a number"));
    CHECK_THROWS_WITH(config::parse_config("[simulation]\nfaults = [3]\n", "lab.toml"),
                      Catch::Contains("simulation.faults: expected strings"));
    CHECK_THROWS_WITH(config::parse_config("[api]\ntcp_port = 70000\n", "lab.toml"), Catch::Contains("api.tcp_port"));
    CHECK_THROWS_WITH(parse_campaign_plan("name = \"x\"\n[[cases]]\nchamber_temp_c = 35\n", "c.toml"),
                      Catch::Contains("c.toml") && Catch::Contains("chamber_rh_pct are required"));
    CHECK_THROWS_WITH(parse_campaign_plan("name = \"x\"\nreplicates = 0\nbuiltin_cases = \"table-s3\"\n", "c.toml"),
                      Catch::Contains("c.toml:2") && Catch::Contains("replicates"));
}
