// The simulated Modbus TCP device reads requests in whatever pieces TCP delivers them and cuts
// them by the MBAP length itself (sim/devices/modbus_server.cpp): a request in single bytes, two
// in one segment, and a malformed header that closes that connection and no other.
#include <catch2/catch.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cstdint>
#include <mutex>
#include <vector>

#include "sim/devices/modbus_server.hpp"

using manikind::sim::ServedRegister;
using manikind::sim::VirtualModbusServer;

namespace {

int connect_to(int port) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    REQUIRE(fd >= 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    REQUIRE(::connect(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0);
    const int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);  // each byte its own segment
    timeval guard{30, 0};  // a guard against a hang only: every read below has its answer on the way
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &guard, sizeof guard);
    return fd;
}

// Read holding register 0x0010 (one register), unit 1, transaction `tid`.
std::vector<std::uint8_t> read_request(std::uint8_t tid) { return {0x00, tid, 0x00, 0x00, 0x00, 0x06, 0x01, 0x03, 0x00, 0x10, 0x00, 0x01}; }

// One reply, as long as its MBAP length says (a read of one register: 11 bytes; an exception: 9).
// Empty when the server closed the connection.
std::vector<std::uint8_t> read_reply(int fd) {
    std::vector<std::uint8_t> r;
    std::uint8_t b[64];
    while (r.size() < 6 || r.size() < 6u + ((r[4] << 8) | r[5])) {
        const ssize_t got = ::recv(fd, b, r.size() < 6 ? 6 - r.size() : 6u + ((r[4] << 8) | r[5]) - r.size(), 0);
        if (got <= 0) return {};
        r.insert(r.end(), b, b + got);
    }
    return r;
}

}  // namespace

TEST_CASE("simulated Modbus device: requests in single bytes and two in one segment are answered, a malformed header closes only its connection",
          "[devices][modbus]") {
    std::mutex world_lock;
    manikind::protocol::modbus_registers::RegisterSpec spec;
    spec.name = "air_temp_pv_c";
    spec.address = 0x10;
    spec.scale = 0.1;
    VirtualModbusServer server("chamber", {ServedRegister{spec, 1, std::nullopt, [] { return 23.4; }, {}}}, world_lock);
    server.start();

    const int a = connect_to(server.port());
    for (std::uint8_t byte : read_request(7)) REQUIRE(::send(a, &byte, 1, 0) == 1);
    const auto one = read_reply(a);
    REQUIRE(one.size() == 11);
    CHECK(one[1] == 7);                                 // its transaction id
    CHECK(one[7] == 0x03);                              // function 3, no exception
    CHECK(((one[9] << 8) | one[10]) == 234);            // 23.4 at 0.1 per count

    auto two = read_request(8);
    const auto second = read_request(9);
    two.insert(two.end(), second.begin(), second.end());
    REQUIRE(::send(a, two.data(), two.size(), 0) == static_cast<ssize_t>(two.size()));
    const auto first = read_reply(a), then = read_reply(a);
    REQUIRE(first.size() == 11);
    REQUIRE(then.size() == 11);
    CHECK(first[1] == 8);
    CHECK(then[1] == 9);

    // Protocol id 1: not Modbus. That connection is closed; another client is still served.
    const int c = connect_to(server.port());
    auto bad = read_request(10);
    bad[3] = 0x01;
    REQUIRE(::send(c, bad.data(), bad.size(), 0) == static_cast<ssize_t>(bad.size()));
    CHECK(read_reply(c).empty());
    // A request shorter than any function's fields (unit and function code only, length 2) is
    // refused the same way; nothing is read past its bytes (ASan would say).
    const int d = connect_to(server.port());
    const std::vector<std::uint8_t> stub = {0x00, 0x0c, 0x00, 0x00, 0x00, 0x02, 0x01, 0x03};
    REQUIRE(::send(d, stub.data(), stub.size(), 0) == static_cast<ssize_t>(stub.size()));
    CHECK(read_reply(d).empty());
    ::close(d);
    // A write of many registers whose count claims more than the request holds: answered (an
    // exception or not) without reading past it.
    const std::vector<std::uint8_t> greedy = {0x00, 0x0d, 0x00, 0x00, 0x00, 0x07, 0x01, 0x10, 0x00, 0x10, 0x00, 0x7b, 0xf6};
    REQUIRE(::send(a, greedy.data(), greedy.size(), 0) == static_cast<ssize_t>(greedy.size()));
    const auto refused = read_reply(a);
    REQUIRE(refused.size() == 9);
    CHECK(refused[1] == 0x0d);
    CHECK(refused[7] == (0x10 | 0x80));  // an exception to function 16
    const auto again = read_request(11);
    REQUIRE(::send(a, again.data(), again.size(), 0) == static_cast<ssize_t>(again.size()));
    const auto after = read_reply(a);
    REQUIRE(after.size() == 11);
    CHECK(after[1] == 11);
    CHECK(server.requests() == 5);
    ::close(a);
    ::close(c);
    server.stop();
}
