#pragma once
// A Modbus TCP client on a plain blocking socket (the Modbus Messaging on TCP/IP Implementation
// Guide V1.0b). libmodbus waits in select() before each part of a reply (header, then the rest):
// five system calls a request. Here the requests of one poll go out in one send() and the
// replies come back through one blocking recv() (more only when a reply arrives in pieces): two
// calls for a poll, and the thread wakes once per poll instead of once per request. Requests
// in flight at once are bounded by the caller (`in_flight`): the guide lets a client pipeline
// (3.1.3, transaction ids pair replies with requests), but a real device or gateway may take
// one at a time, so one is the default there (docs/devices.md).
//
// Errors are errno values, or libmodbus's codes (MODBUS_ENOBASE + exception code for an
// exception response, EMBBADDATA for a malformed reply), so the driver classifies both
// backends alike. A timeout, a broken link or a malformed reply closes the connection: bytes
// of unknown meaning may still be in flight.
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "protocol/modbus_tcp_pdu.hpp"

namespace manikind::drivers {

class ModbusTcpClient {
public:
    ModbusTcpClient() = default;
    ModbusTcpClient(const ModbusTcpClient&) = delete;
    ModbusTcpClient& operator=(const ModbusTcpClient&) = delete;
    ~ModbusTcpClient() { close(); }

    // Connects to host (a name or an address) and port within `timeout_s`, which also bounds
    // every reply later. Returns an empty string, or why not.
    std::string connect(const std::string& host, int port, double timeout_s);
    void close();
    bool is_open() const { return fd_ >= 0; }

    struct Call {
        protocol::modbus_tcp::Request request;  // its transaction id is set here
        int err = 0;                            // after transact: 0 or the error
        std::vector<std::uint16_t> words;       // a read's registers
        std::string why;                        // a malformed reply: the field
    };
    // Sends the calls' requests together and reads their replies. Every call gets err 0 or an
    // error. An error that closes the connection goes to the first call not answered; the
    // others not answered carry ENOTCONN.
    // Replies are paired with requests by transaction id, in whatever order they come.
    void transact(std::span<Call> calls);

    // Called after a transaction's requests are sent, before its replies are read: the socket,
    // how many requests went out, and the reply deadline (steady clock, ns). The simulated lab
    // on the virtual clock answers its devices here, on this thread (sim/devices/modbus_server).
    using SentHook = std::function<void(int fd, std::size_t requests, std::int64_t deadline_ns)>;
    void set_sent_hook(SentHook hook) { sent_hook_ = std::move(hook); }

private:
    int receive_some(bool first, std::int64_t deadline_ns);  // bytes appended to in_, or -errno
    void fail_pending(std::span<Call> calls, int err);       // closes; see transact

    SentHook sent_hook_;
    int fd_ = -1;
    double timeout_s_ = 0.5;
    std::uint16_t next_transaction_ = 1;
    std::vector<std::uint8_t> out_;
    std::vector<std::uint8_t> in_;
};

}  // namespace manikind::drivers
