#pragma once
// The simulated lab: the world plus one virtual device per instrument, each speaking the real
// protocol over a real transport, so the daemon's drivers cannot tell it from the lab:
//   chamber controller, datalogger  -> libmodbus TCP servers on 127.0.0.1
//   WindSonic, CSAT3B               -> pseudo-terminals (stable symlinks in the runtime dir)
//   manikin zone bus                -> a SOCK_SEQPACKET socketpair carrying struct can_frame
// Time advances only through step(dt) (the virtual clock); run it as fast as the CPU allows or
// paced by the wall clock. Faults are injected by spec (see parse_fault), now or on a schedule.
#include <linux/can.h>

#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "protocol/modbus_registers.hpp"
#include "protocol/probe_scaling.hpp"
#include "sim/devices/modbus_server.hpp"
#include "sim/devices/pty_endpoint.hpp"
#include "sim/world/world.hpp"

namespace manikind::sim {

struct RegisterDef {
    protocol::modbus_registers::RegisterSpec spec;
    int unit_id = 1;
    std::optional<protocol::ProbeScaling> probe;
};

// device:fault[=value][@start_s[-end_s]], e.g. "windsonic:silent@1200-1260",
// "manikin:heater_fail=12", "chamber:exception", "csat3b:bad_checksum", "manikin:bus_off@600".
struct FaultSpec {
    std::string device;     // windsonic | csat3b | chamber | datalogger | manikin
    std::string fault;      // see fault_help()
    double value = 0.0;     // zone number, status code ...
    double start_s = -1.0;  // virtual time; < 0 = now
    double end_s = -1.0;    // < 0 = until cleared
    std::string text;
};
FaultSpec parse_fault(const std::string& text);  // throws std::invalid_argument with what was expected
const char* fault_help();

struct SimLabOptions {
    WorldOptions world;
    std::vector<RegisterDef> chamber_registers;      // config/chamber_registers.toml
    std::vector<RegisterDef> datalogger_registers;   // config/datalogger_registers.toml
    std::filesystem::path runtime_dir;               // pty links live here; created if missing
    double windsonic_period_s = 1.0;                 // WindSonic default output rate 1 Hz
    double csat3b_period_s = 1.0;                    // CSAT3B runs 10-100 Hz; 1 Hz keeps virtual runs light
    double manikin_period_s = 1.0;
    int chamber_port = 0, datalogger_port = 0;       // 0: the kernel picks a free port
    std::vector<FaultSpec> faults;                   // scheduled faults
};

struct SimEndpoints {
    std::string chamber_host = "127.0.0.1";
    int chamber_port = 0;
    std::vector<int> chamber_units;
    int datalogger_port = 0;
    std::vector<int> datalogger_units;
    std::string windsonic_path, csat3b_path;          // stable links
    std::string windsonic_pty, csat3b_pty;            // current /dev/pts/N
};

class SimLab {
public:
    explicit SimLab(SimLabOptions options);
    ~SimLab();
    SimLab(const SimLab&) = delete;
    SimLab& operator=(const SimLab&) = delete;

    SimEndpoints endpoints() const;
    // The host's end of the manikin bus (once; the caller owns it).
    int take_manikin_fd();

    // Advances virtual time: the world, then every device's output for this interval.
    void step(double dt_s);
    double time_s() const;

    // Serial bytes written during the last step, per device (the lockstep waits for them).
    std::uint64_t serial_bytes_last_step(const std::string& device) const;
    std::uint64_t can_frames_last_step() const { return can_frames_last_step_; }

    void inject(const FaultSpec& fault);   // starts now unless start_s is in the future
    // The operator dresses the manikin (clothing tests): a wardrobe ensemble by id ("nude" or
    // empty: bare). Returns false for an id the wardrobe does not have (the manikin stays bare).
    bool dress(const std::string& ensemble);
    // The room a case states ([[cases.local]], per zone; empty: the configured room). False: wrong size.
    bool set_room(const std::vector<physics::twin::LocalEnvironment>& room);
    void clear_faults(const std::string& device);
    std::vector<std::string> active_faults() const;

    // The virtual clock: the chamber and datalogger answer on the caller's thread, inside the
    // driver's transaction (answer_modbus), instead of on their own threads: no hand-off per
    // request. false: their own threads again (real-time pacing).
    void serve_modbus_on_caller(bool on);
    // Caller mode: the device ("chamber" or "datalogger") answers what was sent to it; see
    // VirtualModbusServer::serve_until.
    VirtualModbusServer::Served answer_modbus(const std::string& device, int client_fd, std::uint64_t requests, std::int64_t deadline_ns);

    // The world, under its lock (the Modbus servers read it from their threads).
    std::mutex& world_lock() { return world_lock_; }
    World& world() { return world_; }

private:
    struct SerialDevice;
    void apply_schedule();
    bool fault_active(const std::string& device, const std::string& fault) const;
    double fault_value(const std::string& device, const std::string& fault) const;
    void manikin_io();
    void serial_output(SerialDevice& d, bool host_sent);
    std::vector<ServedRegister> bind_chamber(const std::vector<RegisterDef>& defs);
    std::vector<ServedRegister> bind_datalogger(const std::vector<RegisterDef>& defs);
    void update_modbus_faults();

    SimLabOptions o_;
    mutable std::mutex world_lock_;
    World world_;
    std::unique_ptr<VirtualModbusServer> chamber_, datalogger_;
    std::map<std::string, double> controller_memory_;   // registers the world does not model
    std::unique_ptr<SerialDevice> windsonic_, csat3b_;
    int manikin_fd_ = -1, host_fd_ = -1;
    double manikin_due_s_ = 0.0;
    std::uint8_t heartbeat_seq_ = 0;
    std::uint64_t can_frames_last_step_ = 0;
    std::map<int, double> stuck_skin_;                   // zone -> frozen reading
    std::vector<FaultSpec> scheduled_;
    std::vector<FaultSpec> active_;
    std::mt19937_64 rng_;
};

}  // namespace manikind::sim
