// On the virtual clock the simulated Modbus devices answer on the thread that asks, inside the
// driver's transaction (VirtualModbusServer::serve_until, called from the client's sent hook),
// instead of on their own threads: same sockets, same bytes, no thread hand-off per request
// (issue 36). These check that the own thread is really gone in caller mode, that a connection
// made before the switch is served after it, that pipelined requests are answered in one call,
// that a silent device returns at once (the client's own timeout does the waiting), and that
// switching back restores the own thread.
#include <catch2/catch.hpp>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <vector>

#include "drivers/modbus_tcp_client.hpp"
#include "protocol/modbus_tcp_pdu.hpp"
#include "sim/devices/modbus_server.hpp"

using manikind::drivers::ModbusTcpClient;
using manikind::sim::ModbusFaults;
using manikind::sim::ServedRegister;
using manikind::sim::VirtualModbusServer;

namespace {

std::vector<ModbusTcpClient::Call> reads(std::initializer_list<std::uint16_t> addresses) {
    std::vector<ModbusTcpClient::Call> calls;
    for (const auto a : addresses) {
        ModbusTcpClient::Call c;
        c.request.unit = 1;
        c.request.function = manikind::protocol::modbus_tcp::kReadHolding;
        c.request.address = a;
        c.request.count = 1;
        calls.push_back(std::move(c));
    }
    return calls;
}

std::int64_t steady_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct Device {
    std::mutex world_lock;
    double air_c = 23.4, rh_pct = 41.0;
    VirtualModbusServer server{"chamber", registers(), world_lock};

    std::vector<ServedRegister> registers() {
        manikind::protocol::modbus_registers::RegisterSpec t, h;
        t.name = "air_temp_pv_c";
        t.address = 0x10;
        t.scale = 0.1;
        h.name = "air_rh_pv_pct";
        h.address = 0x11;
        h.scale = 0.1;
        return {ServedRegister{t, 1, std::nullopt, [this] { return air_c; }, {}},
                ServedRegister{h, 1, std::nullopt, [this] { return rh_pct; }, {}}};
    }
};

}  // namespace

TEST_CASE("simulated Modbus device on the caller's thread: no own thread, a connection kept across the switch, "
          "pipelined requests answered in one call, a silent device returns at once, and back again",
          "[devices][modbus]") {
    Device d;
    d.server.start();
    ModbusTcpClient before;  // connected while the device still has its own thread
    REQUIRE(before.connect("127.0.0.1", d.server.port(), 5.0).empty());
    auto first = reads({0x10});
    before.transact(first);
    REQUIRE(first[0].err == 0);
    CHECK(first[0].words == std::vector<std::uint16_t>{234});

    d.server.serve_on_caller();
    REQUIRE(d.server.serving_on_caller());

    SECTION("with nobody serving, a request goes unanswered: the own thread is gone") {
        ModbusTcpClient lonely;
        REQUIRE(lonely.connect("127.0.0.1", d.server.port(), 0.2).empty());  // the kernel completes it
        auto calls = reads({0x10});
        lonely.transact(calls);
        CHECK(calls[0].err == ETIMEDOUT);
    }

    SECTION("the sent hook answers pipelined requests in one call, on a connection made before the switch") {
        std::vector<VirtualModbusServer::Served> served;
        before.set_sent_hook([&](int fd, std::size_t n, std::int64_t deadline_ns) {
            served.push_back(d.server.serve_until(fd, n, deadline_ns));
        });
        d.air_c = 30.5;
        auto calls = reads({0x10, 0x11});
        const auto requests0 = d.server.requests();
        before.transact(calls);
        REQUIRE(calls[0].err == 0);
        REQUIRE(calls[1].err == 0);
        CHECK(calls[0].words == std::vector<std::uint16_t>{305});  // the world as it is now
        CHECK(calls[1].words == std::vector<std::uint16_t>{410});
        REQUIRE(served.size() == 1);
        CHECK(served[0].answered == 2);
        CHECK_FALSE(served[0].deadline_passed);
        CHECK(d.server.requests() - requests0 == 2);
    }

    SECTION("asked for more than was sent, it stops when the reply is waiting, not at the deadline") {
        ModbusTcpClient c;
        REQUIRE(c.connect("127.0.0.1", d.server.port(), 5.0).empty());
        VirtualModbusServer::Served served;
        c.set_sent_hook([&](int fd, std::size_t, std::int64_t) {
            served = d.server.serve_until(fd, 5, steady_ns() + std::int64_t{3600} * 1'000'000'000);
        });
        auto calls = reads({0x11});
        c.transact(calls);
        CHECK(calls[0].err == 0);
        CHECK(served.answered == 1);
        CHECK(served.reply_waiting);
        CHECK_FALSE(served.deadline_passed);
    }

    SECTION("a silent device: the request counts as answered, the call returns, the client times out itself") {
        ModbusFaults f;
        f.silent = true;
        d.server.set_faults(f);
        ModbusTcpClient c;
        REQUIRE(c.connect("127.0.0.1", d.server.port(), 0.2).empty());
        VirtualModbusServer::Served served;
        c.set_sent_hook([&](int fd, std::size_t n, std::int64_t) {
            served = d.server.serve_until(fd, n, steady_ns() + std::int64_t{3600} * 1'000'000'000);
        });
        auto calls = reads({0x10});
        c.transact(calls);
        CHECK(calls[0].err == ETIMEDOUT);
        CHECK(served.answered == 1);
        CHECK_FALSE(served.reply_waiting);
        CHECK_FALSE(served.deadline_passed);
    }

    SECTION("switched back, its own thread answers again, and serve_until leaves the sockets alone") {
        d.server.serve_on_own_thread();
        CHECK_FALSE(d.server.serving_on_caller());
        CHECK(d.server.serve_until(-1, 1, steady_ns()).answered == 0);
        auto calls = reads({0x11});
        before.transact(calls);
        REQUIRE(calls[0].err == 0);
        CHECK(calls[0].words == std::vector<std::uint16_t>{410});
    }
    d.server.stop();
}
