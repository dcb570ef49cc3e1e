// Every driver against its virtual device over the real transport, on the virtual clock.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "lab_fixture.hpp"

using manikind::drivers::Quality;
using manikind::test::LabFixture;
namespace mc = manikind::protocol::manikin_can;

TEST_CASE("simulated lab: every device delivers good samples over its real transport", "[devices]") {
    LabFixture lab;
    lab.run_s(60);
    CHECK(lab.channel("windsonic", "air_speed_m_s").good >= 58);
    CHECK(lab.channel("csat3b", "sonic_temp_c").good >= 58);
    CHECK(lab.channel("chamber", "air_temp_pv_c").good >= 59);
    CHECK(lab.channel("chamber", "air_rh_pv_pct").good >= 59);
    const auto probe = lab.channel("datalogger", "ee181_1.air_temp_c");
    CHECK(probe.good >= 59);
    CHECK(probe.last.value == Approx(22.0).margin(0.3));  // initial chamber temperature
    CHECK(lab.channel("datalogger", "wall_tc_4.wall_temp_c").good >= 59);
    for (int z : {1, 18, 35}) {
        char name[32];
        std::snprintf(name, sizeof name, "z%02d.skin_temp_c", z);
        CHECK(lab.channel("manikin", name).good >= 59);
    }
    for (const auto& s : lab.acq().status()) {
        INFO(s.name << ": " << s.last_error);
        CHECK(s.connected);
        CHECK(s.checksum_errors == 0);
        CHECK(s.timeouts == 0);
        CHECK(s.reconnects == 0);
    }
    CHECK(lab.acq().lockstep_stalls() == 0);
    // Timestamps come from the virtual clock: 60 s have passed, not the wall clock's few ms.
    CHECK(lab.channel("windsonic", "air_speed_m_s").last.mono_ns == 60'000'000'000LL);
}

TEST_CASE("chamber setpoint written over Modbus moves the simulated chamber", "[devices]") {
    LabFixture lab;
    REQUIRE(lab.acq().chamber().write("air_temp_remote_setpoint_c", 35.0).empty());
    REQUIRE(lab.acq().chamber().write("air_rh_remote_setpoint_pct", 27.0).empty());
    lab.run_s(3600, 5.0);
    CHECK(lab.channel("chamber", "air_temp_pv_c").last.value == Approx(35.0).margin(0.2));
    CHECK(lab.channel("chamber", "air_temp_working_setpoint_c").last.value == Approx(35.0));
    CHECK(lab.channel("chamber", "air_temp_remote_setpoint_c").count == 0);  // written, not polled
    CHECK(*lab.acq().chamber().read("air_temp_remote_setpoint_c") == Approx(35.0));
    // Table S3 case 5: chamber 35 °C / 27 % gives enclosure air 35.3 °C / 35.6 %.
    CHECK(lab.channel("datalogger", "ee181_1.air_temp_c").last.value == Approx(35.3).margin(0.25));
    CHECK(lab.channel("datalogger", "ee181_1.air_rh_pct").last.value == Approx(35.6).margin(1.5));
}

TEST_CASE("a setpoint outside the register's limits is refused before anything is sent", "[devices]") {
    LabFixture lab;
    const auto requests = lab.acq().chamber().status().frames;
    const std::string why = lab.acq().chamber().write("air_temp_remote_setpoint_c", 80.0);
    CHECK(why.find("air_temp_remote_setpoint_c") != std::string::npos);
    CHECK(why.find("55") != std::string::npos);
    CHECK(lab.acq().chamber().status().frames == requests);
    CHECK(lab.lab().world().chamber_temp_setpoint_c() == Approx(22.0));
    CHECK_FALSE(lab.acq().chamber().write("air_temp_pv_c", 30.0).empty());  // read-only
}

TEST_CASE("the manikin holds its skin setpoint under its own PI loop, commanded over CAN", "[devices]") {
    LabFixture lab;
    mc::Setpoint sp;
    sp.zone = 0;
    sp.mode = mc::ControlMode::constant_skin_temp;
    sp.value = 35.0;
    REQUIRE(lab.acq().manikin().send(sp));
    REQUIRE(lab.acq().manikin().set_run(true));
    lab.run_s(2700, 1.0);
    for (int z : {1, 10, 23, 35}) {
        char name[32];
        std::snprintf(name, sizeof name, "z%02d.skin_temp_c", z);
        INFO(name);
        CHECK(lab.channel("manikin", name).last.value == Approx(35.0).margin(0.05));
        std::snprintf(name, sizeof name, "z%02d.heat_flux_w_m2", z);
        CHECK(lab.channel("manikin", name).last.value > 20.0);  // 35 °C skin in 22 °C air loses heat
    }
    const auto hb = lab.acq().manikin().last_heartbeat();
    REQUIRE(hb);
    CHECK(hb->mode == mc::ControlMode::constant_skin_temp);
    CHECK(hb->error_bits == 0);
}

TEST_CASE("the manikin's watchdog stops heating when the host heartbeat stalls", "[devices]") {
    LabFixture lab;
    mc::Setpoint sp;
    sp.value = 35.0;
    lab.acq().manikin().send(sp);
    lab.acq().manikin().set_run(true);
    lab.run_s(30);
    // The host goes quiet: step the lab alone, as if the daemon had hung.
    for (int i = 0; i < 15; ++i) lab.lab().step(1.0);  // past [safety] watchdog_timeout_s = 10 s
    CHECK(lab.lab().world().watchdog_tripped());
    CHECK(lab.lab().world().zone(5).heater_power_w_m2 == 0.0);
    lab.run_s(2);
    REQUIRE(lab.acq().manikin().last_heartbeat());
    CHECK(lab.acq().manikin().last_heartbeat()->error_bits == 1);
    CHECK(lab.acq().manikin().status().device_faults >= 1);
}

TEST_CASE("the datalogger's eight inputs are polled in one Modbus request (registers 0-19, across the unused 4-15), not eight", "[devices][modbus]") {
    // max_gap_registers (default 16) bridges the 12 unused registers between the probes' 0..3
    // and the thermocouples' 16..19; 0 reads the two contiguous runs.
    for (const int max_gap : {16, 0}) {
        INFO("max_gap_registers = " << max_gap);
        auto cfg = manikind::test::LabFixture::quick_config();
        cfg.devices.datalogger.max_gap_registers = max_gap;
        manikind::test::LabFixture lab(cfg);
        lab.run_s(3.0);
        lab.reset_counts();
        const auto before = lab.status("datalogger");
        lab.run_s(10.0);
        const auto after = lab.status("datalogger");
        const std::size_t polls = lab.channel("datalogger", "ee181_1.air_temp_c").count;
        REQUIRE(polls >= 5);
        // Every point still arrives, good, once per poll.
        for (const char* ch : {"ee181_1.air_temp_c", "ee181_1.air_rh_pct", "ee181_2.air_temp_c", "ee181_2.air_rh_pct",
                               "wall_tc_1.wall_temp_c", "wall_tc_2.wall_temp_c", "wall_tc_3.wall_temp_c", "wall_tc_4.wall_temp_c"}) {
            INFO(ch);
            CHECK(lab.channel("datalogger", ch).count == polls);
            CHECK(lab.channel("datalogger", ch).good == polls);
        }
        // One answered request per block, and none refused.
        CHECK(after.frames - before.frames == (max_gap >= 12 ? 1 : 2) * polls);
        CHECK(after.samples - before.samples == 8 * polls);
        CHECK(after.exceptions == before.exceptions);
    }
}

TEST_CASE("the simulated lab is repeatable: one seed gives every channel the same values, though the datalogger's poll "
          "overlaps the chamber's and the bus reads", "[devices][lockstep]") {
    // The world draws sensor noise from one stream at each reading, so a run repeats only if the
    // readings come in the same order: the step overlaps the datalogger's Modbus round trips with
    // the chamber's (which read no noise) and the manikin frames (drawn before, in the lab step).
    auto run = [] {
        manikind::test::LabFixture lab;
        lab.run_s(120.0);
        std::map<std::string, std::vector<double>> values;
        for (const char* key : {"datalogger/ee181_1.air_temp_c", "datalogger/ee181_2.air_rh_pct", "datalogger/wall_tc_3.wall_temp_c",
                                "chamber/air_temp_pv_c", "manikin/z01.skin_temp_c", "manikin/z35.heat_flux_w_m2",
                                "windsonic/air_speed_m_s", "csat3b/air_speed_m_s"}) {
            const std::string k(key);
            const auto slash = k.find('/');
            values[k] = lab.channel(k.substr(0, slash), k.substr(slash + 1)).values;
        }
        return values;
    };
    const auto first = run();
    const auto second = run();
    for (const auto& [key, v] : first) {
        INFO(key);
        CHECK(v.size() >= 100);
        CHECK(v == second.at(key));
    }
}
