// Injected faults: each driver degrades its samples, counts what happened, and recovers.
#include <catch2/catch.hpp>

#include <unistd.h>

#include "lab_fixture.hpp"

using manikind::drivers::Quality;
using manikind::sim::parse_fault;
using manikind::test::LabFixture;

namespace {
const char* speed_channel = "air_speed_m_s";
}

TEST_CASE("serial anemometer faults: silence, garbage, bad checksums, status codes, hang-up", "[devices][faults]") {
    for (const std::string device : {"windsonic", "csat3b"}) {
        DYNAMIC_SECTION(device) {
            LabFixture lab;
            lab.run_s(10);
            REQUIRE(lab.status(device).connected);

            lab.lab().inject(parse_fault(device + ":silent"));
            lab.run_s(10);
            CHECK(lab.status(device).stale);
            CHECK(lab.status(device).timeouts == 1);
            CHECK(lab.channel(device, speed_channel).n(Quality::stale) >= 1);
            lab.lab().clear_faults(device);
            lab.reset_counts();
            lab.run_s(5);
            CHECK_FALSE(lab.status(device).stale);
            CHECK(lab.channel(device, speed_channel).good >= 4);

            lab.lab().inject(parse_fault(device + ":garbage"));
            lab.reset_counts();
            lab.run_s(20);
            lab.lab().clear_faults(device);
            const auto after_garbage = lab.status(device);
            CHECK(after_garbage.malformed + after_garbage.checksum_errors >= 1);
            if (device == "windsonic") {
                // STX framing: the parser skips the noise and still reads the frame after it.
                CHECK(lab.channel(device, speed_channel).good >= 15);
            } else {
                // Line framing: noise before a record corrupts that record (counted, dropped).
                CHECK(after_garbage.malformed + after_garbage.checksum_errors >= 10);
            }
            lab.reset_counts();
            lab.run_s(5);
            CHECK(lab.channel(device, speed_channel).good >= 4);  // resynchronised at the next terminator

            const auto cs0 = lab.status(device).checksum_errors;
            lab.lab().inject(parse_fault(device + ":bad_checksum"));
            lab.reset_counts();
            lab.run_s(10);
            lab.lab().clear_faults(device);
            CHECK(lab.status(device).checksum_errors - cs0 >= 9);
            CHECK(lab.channel(device, speed_channel).good == 0);  // nothing with a bad checksum gets through

            lab.lab().inject(parse_fault(device + (device == "windsonic" ? ":status=4" : ":status=16")));
            lab.reset_counts();
            lab.run_s(5);
            lab.lab().clear_faults(device);
            CHECK(lab.channel(device, speed_channel).n(Quality::out_of_range) >= 4);
            CHECK(lab.status(device).device_faults >= 4);

            lab.lab().inject(parse_fault(device + ":hang_up"));
            lab.run_s(5);
            const auto st = lab.status(device);
            CHECK(st.reconnects == 1);
            CHECK(st.connected);
            lab.reset_counts();
            lab.run_s(5);
            CHECK(lab.channel(device, speed_channel).good >= 4);
        }
    }
}

TEST_CASE("Modbus faults: timeouts, exceptions, dropped connections, then recovery", "[devices][faults]") {
    for (const std::string device : {"chamber", "datalogger"}) {
        DYNAMIC_SECTION(device) {
            LabFixture lab;
            const std::string ch = device == "chamber" ? "air_temp_pv_c" : "ee181_1.air_temp_c";
            lab.run_s(5);
            REQUIRE(lab.channel(device, ch).good >= 4);

            lab.lab().inject(parse_fault(device + ":silent"));
            lab.reset_counts();
            lab.run_s(3);
            CHECK(lab.status(device).timeouts >= 1);
            CHECK(lab.channel(device, ch).n(Quality::comm_error) >= 1);
            CHECK(lab.channel(device, ch).good == 0);
            lab.lab().clear_faults(device);
            lab.run_s(15);  // backoff, reconnect
            CHECK(lab.status(device).reconnects >= 1);
            lab.reset_counts();
            lab.run_s(3);
            CHECK(lab.channel(device, ch).good >= 2);

            lab.lab().inject(parse_fault(device + ":exception"));
            lab.reset_counts();
            lab.run_s(3);
            lab.lab().clear_faults(device);
            CHECK(lab.status(device).exceptions >= 3);
            CHECK(lab.channel(device, ch).n(Quality::comm_error) >= 3);
            lab.reset_counts();
            lab.run_s(3);
            CHECK(lab.channel(device, ch).good >= 2);  // an exception does not cost the connection

            const auto reconnects = lab.status(device).reconnects;
            lab.lab().inject(parse_fault(device + ":drop"));
            lab.run_s(3);
            lab.lab().clear_faults(device);
            lab.run_s(15);
            CHECK(lab.status(device).reconnects > reconnects);
            lab.reset_counts();
            lab.run_s(3);
            CHECK(lab.channel(device, ch).good >= 2);
        }
    }
}

TEST_CASE("a silent Modbus device costs one timeout per backoff step, not one per register per poll",
          "[devices][faults]") {
    // A silent datalogger used to time out on each of its registers every poll: 4 s of wall
    // time per virtual second, the virtual clock all but stopped.
    LabFixture lab;
    lab.run_s(5);
    lab.lab().inject(parse_fault("datalogger:silent"));
    lab.reset_counts();
    const auto timeouts_before = lab.status("datalogger").timeouts;
    lab.run_s(60);
    const auto timeouts = lab.status("datalogger").timeouts - timeouts_before;
    CHECK(timeouts >= 4);   // it kept trying: 0.5, 1, 2, 4, 8, 10, 10 ... s apart
    CHECK(timeouts <= 12);  // 8 registers x 60 polls before
    CHECK(lab.channel("datalogger", "ee181_1.air_temp_c").good == 0);
    lab.lab().clear_faults("datalogger");
    lab.run_s(15);
    lab.reset_counts();
    lab.run_s(3);
    CHECK(lab.channel("datalogger", "ee181_1.air_temp_c").good >= 2);
}

TEST_CASE("a stuck datalogger keeps serving frozen values", "[devices][faults]") {
    LabFixture lab;
    lab.run_s(3);
    lab.lab().inject(parse_fault("datalogger:stuck"));
    lab.run_s(1);
    const double frozen = lab.channel("datalogger", "ee181_1.air_temp_c").last.value;
    lab.lab().world().set_chamber_setpoints(40.0, 30.0);
    lab.run_s(600, 5.0);
    CHECK(lab.channel("datalogger", "ee181_1.air_temp_c").last.value == frozen);
    lab.lab().clear_faults("datalogger");
    lab.run_s(2);
    CHECK(lab.channel("datalogger", "ee181_1.air_temp_c").last.value > frozen + 1.0);
}

TEST_CASE("manikin bus faults: silence, error frames, bus-off, a failed heater, a stuck sensor", "[devices][faults]") {
    LabFixture lab;
    manikind::protocol::manikin_can::Setpoint sp;
    sp.value = 35.0;
    lab.acq().manikin().send(sp);
    lab.acq().manikin().set_run(true);
    lab.run_s(600);

    lab.lab().inject(parse_fault("manikin:silent"));
    lab.run_s(5);
    CHECK(lab.status("manikin").stale);
    CHECK(lab.status("manikin").timeouts == 1);
    lab.lab().clear_faults("manikin");
    lab.run_s(2);
    CHECK_FALSE(lab.status("manikin").stale);

    lab.lab().inject(parse_fault("manikin:error_frames"));
    lab.run_s(3);
    lab.lab().clear_faults("manikin");
    CHECK(lab.status("manikin").comm_errors >= 3);

    lab.lab().inject(parse_fault("manikin:heater_fail=12"));
    lab.reset_counts();
    lab.run_s(300);
    const auto flux = lab.channel("manikin", "z12.heat_flux_w_m2");
    CHECK(flux.n(Quality::out_of_range) >= 290);
    CHECK(lab.channel("manikin", "z12.skin_temp_c").last.value < 34.0);  // cooling without its heater
    CHECK(lab.channel("manikin", "z11.skin_temp_c").last.value == Approx(35.0).margin(0.1));
    lab.lab().clear_faults("manikin");

    lab.lab().inject(parse_fault("manikin:stuck=3"));
    lab.run_s(1);
    const double stuck = lab.channel("manikin", "z03.skin_temp_c").last.value;
    lab.run_s(30);
    CHECK(lab.channel("manikin", "z03.skin_temp_c").last.value == stuck);
    lab.lab().clear_faults("manikin");

    const auto faults = lab.status("manikin").device_faults;
    lab.lab().inject(parse_fault("manikin:bus_off"));
    lab.run_s(5);
    CHECK(lab.status("manikin").device_faults > faults);
    CHECK(lab.status("manikin").last_error.find("bus-off") != std::string::npos);
    CHECK(lab.status("manikin").stale);
}

TEST_CASE("scheduled faults start and end on the virtual clock", "[devices][faults]") {
    auto cfg = LabFixture::quick_config();
    cfg.simulation.faults = {"windsonic:silent@20-40"};
    LabFixture lab(cfg);
    lab.run_s(19);
    CHECK_FALSE(lab.status("windsonic").stale);
    lab.run_s(10);
    CHECK(lab.status("windsonic").stale);
    lab.run_s(15);
    CHECK_FALSE(lab.status("windsonic").stale);
    CHECK(lab.status("windsonic").timeouts == 1);
}

TEST_CASE("fault specs are parsed strictly with what was expected", "[devices][faults]") {
    const auto f = parse_fault("manikin:heater_fail=12@600-900");
    CHECK(f.device == "manikin");
    CHECK(f.fault == "heater_fail");
    CHECK(f.value == 12);
    CHECK(f.start_s == 600);
    CHECK(f.end_s == 900);
    CHECK_THROWS_WITH(parse_fault("toaster:silent"), Catch::Contains("unknown device 'toaster'"));
    CHECK_THROWS_WITH(parse_fault("windsonic:melt"), Catch::Contains("unknown fault 'melt'"));
    CHECK_THROWS_WITH(parse_fault("windsonic:silent@50-20"), Catch::Contains("end must come after"));
    CHECK_THROWS_WITH(parse_fault("windsonic"), Catch::Contains("missing ':'"));
}
