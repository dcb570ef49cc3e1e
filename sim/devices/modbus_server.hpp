#pragma once
// A virtual Modbus TCP device: a libmodbus server on 127.0.0.1 (port chosen by the kernel
// unless given) serving holding registers per unit id from callbacks into the simulated world.
// Writes within the register's limits reach the world; writes outside them get the exception a
// controller gives (ILLEGAL DATA VALUE); reads of unmapped addresses get ILLEGAL DATA ADDRESS
// from libmodbus itself. Faults: silent (no answer: the client times out), an exception on
// every request, dropping the connection, refusing new connections.
#include <sys/select.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "protocol/modbus_registers.hpp"
#include "protocol/probe_scaling.hpp"

namespace manikind::sim {

struct ServedRegister {
    protocol::modbus_registers::RegisterSpec spec;
    int unit_id = 1;
    std::optional<protocol::ProbeScaling> probe;    // the register holds the probe's raw signal
    std::function<double()> read;                   // engineering value now
    std::function<bool(double)> write;              // empty for read-only; false = refused
};

struct ModbusFaults {
    bool silent = false;        // receive but never answer
    bool exception = false;     // answer every request with SLAVE/SERVER DEVICE FAILURE
    bool drop = false;          // close every client connection as it sends
    bool stuck = false;         // keep serving the values frozen at the moment it was set
};

class VirtualModbusServer {
public:
    // `world_lock` is held while callbacks run (the world steps on another thread).
    VirtualModbusServer(std::string name, std::vector<ServedRegister> registers, std::mutex& world_lock);
    ~VirtualModbusServer();
    VirtualModbusServer(const VirtualModbusServer&) = delete;
    VirtualModbusServer& operator=(const VirtualModbusServer&) = delete;

    void start(int port = 0);   // binds 127.0.0.1; throws std::runtime_error naming the port
    void stop();

    // Who answers. By default the server's own thread, waiting in select. On the virtual clock
    // the acquisition loop answers instead, on its own thread, right after a driver sends
    // (serve_until): the same sockets and bytes, but no thread hand-off per request (issue 36).
    // Switching keeps every connection and what it has sent.
    void serve_on_caller();
    void serve_on_own_thread();
    bool serving_on_caller() const { return on_caller_; }
    // Caller mode: answers what clients have sent until `requests` more have been answered
    // (a silent device counts as answering), `client_fd` (the asking driver's socket) has a
    // reply to read, or `deadline_ns` (steady clock) passes; whichever comes first.
    struct Served {
        std::uint64_t answered = 0;   // requests answered in this call
        bool reply_waiting = false;   // client_fd had bytes to read
        bool deadline_passed = false;
    };
    Served serve_until(int client_fd, std::uint64_t requests, std::int64_t deadline_ns);
    int port() const { return port_; }
    const std::string& name() const { return name_; }
    std::vector<int> unit_ids() const;

    void set_faults(const ModbusFaults& f);
    ModbusFaults faults() const;
    std::uint64_t requests() const { return requests_.load(); }

private:
    void serve();
    // One round: waits in select (up to timeout_ms; -1: no limit) on the listening socket, the
    // clients and `also_fd`, then accepts and answers what came. False when woken to stop.
    // Sets *also_ready when `also_fd` is readable.
    bool serve_round(int timeout_ms, int also_fd, bool* also_ready);
    // Reads the clients `readable` marks (nullptr: every client, without waiting) and answers
    // every whole request they hold. True when any bytes came.
    bool serve_clients(const fd_set* readable);
    bool answer(int c, std::uint8_t* query, int length);
    void start_thread();
    void stop_thread();
    void refresh(int unit);
    bool handle_write(int unit, const std::uint8_t* query, int length, int header);

    std::string name_;
    std::vector<ServedRegister> registers_;
    std::vector<protocol::modbus_registers::RegisterSpec> image_specs_;  // registers_[i] as the image encodes it
    std::mutex& world_lock_;
    std::map<int, void*> mappings_;  // unit id -> modbus_mapping_t*
    void* ctx_ = nullptr;            // modbus_t*
    int listen_fd_ = -1;
    int wake_pipe_[2] = {-1, -1};
    int port_ = 0;
    std::thread thread_;
    std::atomic<bool> stopping_{false};
    std::atomic<bool> on_caller_{false};
    std::mutex serve_lock_;                           // one serve_until at a time (caller mode)
    std::map<int, std::vector<std::uint8_t>> clients_; // each client's bytes not yet a whole request
    mutable std::mutex faults_lock_;
    ModbusFaults faults_;
    std::map<std::string, double> frozen_;
    std::atomic<std::uint64_t> requests_{0};
};

}  // namespace manikind::sim
