// Our Modbus TCP client (drivers/modbus_tcp_client.hpp): against libmodbus's own server (a peer
// not written here) with a poll's requests pipelined, and against a scripted server that answers
// out of order, in single bytes, with a stranger's transaction id, a wrong unit, silence, or a
// closed connection.
#include <catch2/catch.hpp>

#include <arpa/inet.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <functional>
#include <thread>
#include <vector>

#include "drivers/modbus_tcp_client.hpp"
#include "protocol/modbus_tcp_frame.hpp"

using manikind::drivers::ModbusTcpClient;
namespace mtcp = manikind::protocol::modbus_tcp;

namespace {

int listen_loopback(int& port) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    REQUIRE(fd >= 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    REQUIRE(::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0);
    REQUIRE(::listen(fd, 4) == 0);
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port = ntohs(a.sin_port);
    return fd;
}

ModbusTcpClient::Call read_call(std::uint8_t unit, std::uint16_t address, std::uint16_t count, bool input = false) {
    ModbusTcpClient::Call c;
    c.request.unit = unit;
    c.request.function = input ? mtcp::kReadInput : mtcp::kReadHolding;
    c.request.address = address;
    c.request.count = count;
    return c;
}

// A server of our own that reads `n` whole requests from one client and answers with what
// `script` makes of them: byte chunks, each sent alone. Then it waits for the client to close.
struct ScriptedServer {
    using Script = std::function<std::vector<std::vector<std::uint8_t>>(const std::vector<std::vector<std::uint8_t>>&)>;
    int listen_fd = -1;
    int port = 0;
    std::thread thread;
    ScriptedServer(std::size_t n, Script script, bool close_after = false) {
        listen_fd = listen_loopback(port);
        thread = std::thread([this, n, script, close_after] {
            const int c = ::accept(listen_fd, nullptr, nullptr);
            if (c < 0) return;
            const int one = 1;
            ::setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);  // each chunk its own segment
            std::vector<std::uint8_t> in;
            std::vector<std::vector<std::uint8_t>> requests;
            while (requests.size() < n) {
                std::uint8_t buf[512];
                const ssize_t got = ::recv(c, buf, sizeof buf, 0);
                if (got <= 0) break;
                in.insert(in.end(), buf, buf + got);
                for (;;) {
                    const auto f = mtcp::first_frame(in.data(), in.size());
                    if (f.state != mtcp::FrameState::complete) break;
                    requests.emplace_back(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(f.size));
                    in.erase(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(f.size));
                }
            }
            for (const auto& chunk : script(requests)) ::send(c, chunk.data(), chunk.size(), MSG_NOSIGNAL);
            if (!close_after) {
                std::uint8_t buf[64];
                while (::recv(c, buf, sizeof buf, 0) > 0) {
                }
            }
            ::close(c);
        });
    }
    ~ScriptedServer() {
        thread.join();
        ::close(listen_fd);
    }
};

// The reply to a read request: `count` registers holding address + i.
std::vector<std::uint8_t> read_reply(const std::vector<std::uint8_t>& q) {
    const int count = (q[10] << 8) | q[11];
    const int address = (q[8] << 8) | q[9];
    std::vector<std::uint8_t> r(q.begin(), q.begin() + 8);  // MBAP, unit and function echoed
    r[5] = static_cast<std::uint8_t>(3 + 2 * count);
    r.push_back(static_cast<std::uint8_t>(2 * count));
    for (int i = 0; i < count; ++i) {
        r.push_back(static_cast<std::uint8_t>((address + i) >> 8));
        r.push_back(static_cast<std::uint8_t>((address + i) & 0xff));
    }
    return r;
}

}  // namespace

TEST_CASE("Modbus TCP client: a poll's reads pipelined to libmodbus's server, writes, an exception", "[devices][modbus]") {
    // libmodbus's server (not written here): holding and input registers 0..99 of unit 1.
    modbus_t* server = modbus_new_tcp("127.0.0.1", 0);
    REQUIRE(server);
    const int listen_fd = modbus_tcp_listen(server, 1);
    REQUIRE(listen_fd >= 0);
    sockaddr_in a{};
    socklen_t len = sizeof a;
    ::getsockname(listen_fd, reinterpret_cast<sockaddr*>(&a), &len);
    modbus_mapping_t* map = modbus_mapping_new(0, 0, 100, 100);
    REQUIRE(map);
    for (int i = 0; i < 100; ++i) {
        map->tab_registers[i] = static_cast<std::uint16_t>(1000 + i);
        map->tab_input_registers[i] = static_cast<std::uint16_t>(2000 + i);
    }
    std::thread serve([&] {
        int fd = listen_fd;
        if (modbus_tcp_accept(server, &fd) < 0) return;
        std::uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
        for (;;) {
            const int rc = modbus_receive(server, query);
            if (rc < 0) break;  // the client closed
            if (rc > 0) modbus_reply(server, query, rc, map);
        }
    });

    ModbusTcpClient client;
    REQUIRE(client.connect("127.0.0.1", ntohs(a.sin_port), 2.0).empty());
    std::vector<ModbusTcpClient::Call> poll = {read_call(1, 0, 4), read_call(1, 10, 2, true), read_call(1, 99, 2),
                                               read_call(1, 50, 50)};
    client.transact(poll);
    CHECK(poll[0].err == 0);
    CHECK(poll[0].words == std::vector<std::uint16_t>{1000, 1001, 1002, 1003});
    CHECK(poll[1].err == 0);
    CHECK(poll[1].words == std::vector<std::uint16_t>{2010, 2011});
    CHECK(poll[2].err == EMBXILADD);  // register 100 is past the image: exception 2, the link stays
    CHECK(poll[2].words.empty());
    REQUIRE(poll[3].err == 0);
    CHECK(poll[3].words.size() == 50);
    CHECK(poll[3].words.back() == 1099);
    CHECK(client.is_open());

    ModbusTcpClient::Call single;
    single.request.unit = 1;
    single.request.function = mtcp::kWriteSingle;
    single.request.address = 5;
    single.request.values = {4321};
    ModbusTcpClient::Call multiple;
    multiple.request.unit = 1;
    multiple.request.function = mtcp::kWriteMultiple;
    multiple.request.address = 6;
    multiple.request.count = 2;
    multiple.request.values = {7, 8};
    std::vector<ModbusTcpClient::Call> writes = {single, multiple, read_call(1, 5, 3)};
    client.transact(writes);
    CHECK(writes[0].err == 0);
    CHECK(writes[1].err == 0);
    CHECK(writes[2].words == std::vector<std::uint16_t>{4321, 7, 8});  // read after the writes, in order
    CHECK(map->tab_registers[5] == 4321);
    client.close();
    serve.join();
    ::close(listen_fd);
    modbus_mapping_free(map);
    modbus_free(server);
}

TEST_CASE("Modbus TCP client: replies out of order and in single bytes are paired by transaction id", "[devices][modbus]") {
    ScriptedServer s(3, [](const auto& requests) {
        std::vector<std::vector<std::uint8_t>> chunks;
        for (const std::size_t i : {2u, 0u, 1u})
            for (const std::uint8_t b : read_reply(requests[i])) chunks.push_back({b});
        return chunks;
    });
    ModbusTcpClient client;
    REQUIRE(client.connect("127.0.0.1", s.port, 5.0).empty());
    std::vector<ModbusTcpClient::Call> calls = {read_call(1, 10, 1), read_call(2, 20, 2), read_call(3, 30, 3)};
    client.transact(calls);
    CHECK(calls[0].err == 0);
    CHECK(calls[0].words == std::vector<std::uint16_t>{10});
    CHECK(calls[1].words == std::vector<std::uint16_t>{20, 21});
    CHECK(calls[2].words == std::vector<std::uint16_t>{30, 31, 32});
    CHECK(client.is_open());
    client.close();
}

TEST_CASE("Modbus TCP client: a stranger's transaction id or a wrong unit loses the stream, named once", "[devices][modbus]") {
    SECTION("a reply to no request in flight") {
        ScriptedServer s(2, [](const auto& requests) {
            auto r = read_reply(requests[0]);
            r[1] ^= 0x40;  // another transaction id
            return std::vector<std::vector<std::uint8_t>>{r};
        });
        ModbusTcpClient client;
        REQUIRE(client.connect("127.0.0.1", s.port, 5.0).empty());
        std::vector<ModbusTcpClient::Call> calls = {read_call(1, 0, 1), read_call(1, 1, 1)};
        client.transact(calls);
        CHECK(calls[0].err == EMBBADDATA);
        CHECK(calls[0].why.find("no request in flight") != std::string::npos);
        CHECK(calls[1].err == ENOTCONN);  // lost with the link; the failure is counted once
        CHECK_FALSE(client.is_open());
    }
    SECTION("a reply from another unit") {
        ScriptedServer s(2, [](const auto& requests) {
            auto first = read_reply(requests[0]);
            auto second = read_reply(requests[1]);
            second[6] = 9;
            return std::vector<std::vector<std::uint8_t>>{first, second};
        });
        ModbusTcpClient client;
        REQUIRE(client.connect("127.0.0.1", s.port, 5.0).empty());
        std::vector<ModbusTcpClient::Call> calls = {read_call(1, 0, 1), read_call(1, 1, 1)};
        client.transact(calls);
        CHECK(calls[0].err == 0);  // answered before the stream went wrong
        CHECK(calls[1].err == EMBBADDATA);
        CHECK(calls[1].why.find("unit 9") != std::string::npos);
        CHECK_FALSE(client.is_open());
    }
}

TEST_CASE("Modbus TCP client: silence is a timeout, a closed connection a reset, and both close the link", "[devices][modbus]") {
    SECTION("silent") {
        ScriptedServer s(1, [](const auto&) { return std::vector<std::vector<std::uint8_t>>{}; });
        ModbusTcpClient client;
        REQUIRE(client.connect("127.0.0.1", s.port, 0.2).empty());
        std::vector<ModbusTcpClient::Call> calls = {read_call(1, 0, 1)};
        client.transact(calls);
        CHECK(calls[0].err == ETIMEDOUT);
        CHECK_FALSE(client.is_open());
    }
    SECTION("half a reply, then silence") {
        ScriptedServer s(1, [](const auto& requests) {
            auto r = read_reply(requests[0]);
            r.resize(r.size() - 1);
            return std::vector<std::vector<std::uint8_t>>{r};
        });
        ModbusTcpClient client;
        REQUIRE(client.connect("127.0.0.1", s.port, 0.2).empty());
        std::vector<ModbusTcpClient::Call> calls = {read_call(1, 0, 2)};
        client.transact(calls);
        CHECK(calls[0].err == ETIMEDOUT);
        CHECK_FALSE(client.is_open());
    }
    SECTION("closed") {
        ScriptedServer s(1, [](const auto&) { return std::vector<std::vector<std::uint8_t>>{}; }, true);
        ModbusTcpClient client;
        REQUIRE(client.connect("127.0.0.1", s.port, 5.0).empty());
        std::vector<ModbusTcpClient::Call> calls = {read_call(1, 0, 1), read_call(1, 1, 1)};
        client.transact(calls);
        CHECK(calls[0].err == ECONNRESET);
        CHECK(calls[1].err == ENOTCONN);
        CHECK_FALSE(client.is_open());
        client.transact(calls);  // closed: nothing sent
        CHECK(calls[0].err == ENOTCONN);
    }
    SECTION("nobody listening, and a host that does not resolve") {
        int port = 0;
        const int fd = listen_loopback(port);
        ::close(fd);  // the port is free again: a connect is refused
        ModbusTcpClient client;
        CHECK_FALSE(client.connect("127.0.0.1", port, 1.0).empty());
        CHECK_FALSE(client.is_open());
        CHECK(client.connect("no-such-host.invalid", 502, 1.0).find("resolve") != std::string::npos);
    }
}
