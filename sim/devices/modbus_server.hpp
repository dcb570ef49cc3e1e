#pragma once
// A virtual Modbus TCP device: a libmodbus server on 127.0.0.1 (port chosen by the kernel
// unless given) serving holding registers per unit id from callbacks into the simulated world.
// Writes within the register's limits reach the world; writes outside them get the exception a
// controller gives (ILLEGAL DATA VALUE); reads of unmapped addresses get ILLEGAL DATA ADDRESS
// from libmodbus itself. Faults: silent (no answer: the client times out), an exception on
// every request, dropping the connection, refusing new connections.
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
    int port() const { return port_; }
    const std::string& name() const { return name_; }
    std::vector<int> unit_ids() const;

    void set_faults(const ModbusFaults& f);
    ModbusFaults faults() const;
    std::uint64_t requests() const { return requests_.load(); }

private:
    void serve();
    void refresh(int unit);
    bool handle_write(int unit, const std::uint8_t* query, int length, int header);

    std::string name_;
    std::vector<ServedRegister> registers_;
    std::mutex& world_lock_;
    std::map<int, void*> mappings_;  // unit id -> modbus_mapping_t*
    void* ctx_ = nullptr;            // modbus_t*
    int listen_fd_ = -1;
    int wake_pipe_[2] = {-1, -1};
    int port_ = 0;
    std::thread thread_;
    std::atomic<bool> stopping_{false};
    mutable std::mutex faults_lock_;
    ModbusFaults faults_;
    std::map<std::string, double> frozen_;
    std::atomic<std::uint64_t> requests_{0};
};

}  // namespace manikind::sim
