#include "sim/lab/sim_lab.hpp"
#include "sim/world/wardrobe.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <stdexcept>

#include <linux/can/error.h>

#include "protocol/csat3b.hpp"
#include "protocol/manikin_can.hpp"
#include "protocol/windsonic.hpp"

namespace manikind::sim {

namespace mc = protocol::manikin_can;

const char* fault_help() {
    return "device:fault[=value][@start_s[-end_s]]\n"
           "  windsonic|csat3b: silent, garbage, bad_checksum, status=<code|diag bits>, stuck, hang_up\n"
           "  chamber|datalogger: silent (timeouts), exception, drop (connection closed), stuck\n"
           "  manikin: silent, error_frames, bus_off, heater_fail=<zone>, stuck=<zone> (skin sensor)\n"
           "  e.g. windsonic:silent@1200-1260   manikin:heater_fail=12   chamber:exception@600";
}

FaultSpec parse_fault(const std::string& text) {
    FaultSpec f;
    f.text = text;
    const auto bad = [&](const std::string& why) {
        return std::invalid_argument("fault '" + text + "': " + why + "\nexpected " + fault_help());
    };
    std::string rest = text;
    if (const auto at = rest.find('@'); at != std::string::npos) {
        const std::string when = rest.substr(at + 1);
        rest = rest.substr(0, at);
        const auto dash = when.find('-');
        auto num = [&](const std::string& s) {
            double v = 0;
            const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
            if (r.ec != std::errc() || r.ptr != s.data() + s.size() || v < 0) throw bad("'" + s + "' is not a time in s");
            return v;
        };
        f.start_s = num(when.substr(0, dash));
        if (dash != std::string::npos) {
            f.end_s = num(when.substr(dash + 1));
            if (f.end_s <= f.start_s) throw bad("the end must come after the start");
        }
    }
    const auto colon = rest.find(':');
    if (colon == std::string::npos) throw bad("missing ':' between device and fault");
    f.device = rest.substr(0, colon);
    std::string fault = rest.substr(colon + 1);
    if (const auto eq = fault.find('='); eq != std::string::npos) {
        const std::string v = fault.substr(eq + 1);
        const auto r = std::from_chars(v.data(), v.data() + v.size(), f.value);
        if (r.ec != std::errc() || r.ptr != v.data() + v.size()) throw bad("'" + v + "' is not a number");
        fault = fault.substr(0, eq);
    }
    f.fault = fault;
    static const std::map<std::string, std::vector<std::string>> known = {
        {"windsonic", {"silent", "garbage", "bad_checksum", "status", "stuck", "hang_up"}},
        {"csat3b", {"silent", "garbage", "bad_checksum", "status", "stuck", "hang_up"}},
        {"chamber", {"silent", "exception", "drop", "stuck"}},
        {"datalogger", {"silent", "exception", "drop", "stuck"}},
        {"manikin", {"silent", "error_frames", "bus_off", "heater_fail", "stuck"}}};
    const auto dev = known.find(f.device);
    if (dev == known.end()) throw bad("unknown device '" + f.device + "'");
    if (std::find(dev->second.begin(), dev->second.end(), f.fault) == dev->second.end())
        throw bad("unknown fault '" + f.fault + "' for " + f.device);
    return f;
}

struct SimLab::SerialDevice {
    std::string name;
    std::unique_ptr<PtyEndpoint> pty;
    double period_s = 1.0;
    double due_s = 0.0;
    std::uint64_t bytes_last_step = 0;
    int counter = 0;
    std::string last_line;
};

SimLab::SimLab(SimLabOptions options) : o_(std::move(options)), world_(o_.world), rng_(o_.world.seed + 17) {
    std::filesystem::create_directories(o_.runtime_dir);
    windsonic_ = std::make_unique<SerialDevice>();
    windsonic_->name = "windsonic";
    windsonic_->pty = std::make_unique<PtyEndpoint>(o_.runtime_dir / "windsonic");
    windsonic_->period_s = o_.windsonic_period_s;
    csat3b_ = std::make_unique<SerialDevice>();
    csat3b_->name = "csat3b";
    csat3b_->pty = std::make_unique<PtyEndpoint>(o_.runtime_dir / "csat3b");
    csat3b_->period_s = o_.csat3b_period_s;

    int sv[2];
    if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0)
        throw std::runtime_error("socketpair(AF_UNIX, SOCK_SEQPACKET) failed");
    manikin_fd_ = sv[0];
    host_fd_ = sv[1];
    ::fcntl(manikin_fd_, F_SETFL, ::fcntl(manikin_fd_, F_GETFL) | O_NONBLOCK);

    chamber_ = std::make_unique<VirtualModbusServer>("chamber", bind_chamber(o_.chamber_registers), world_lock_);
    datalogger_ =
        std::make_unique<VirtualModbusServer>("datalogger", bind_datalogger(o_.datalogger_registers), world_lock_);
    chamber_->start(o_.chamber_port);
    datalogger_->start(o_.datalogger_port);
    for (const auto& f : o_.faults) inject(f);
}

SimLab::~SimLab() {
    chamber_->stop();
    datalogger_->stop();
    if (manikin_fd_ >= 0) ::close(manikin_fd_);
    if (host_fd_ >= 0) ::close(host_fd_);
}

void SimLab::serve_modbus_on_caller(bool on) {
    for (auto* server : {chamber_.get(), datalogger_.get()}) {
        if (on) server->serve_on_caller();
        else server->serve_on_own_thread();
    }
}

VirtualModbusServer::Served SimLab::answer_modbus(const std::string& device, int client_fd, std::uint64_t requests,
                                    std::int64_t deadline_ns) {
    VirtualModbusServer* server = device == "chamber" ? chamber_.get() : device == "datalogger" ? datalogger_.get() : nullptr;
    if (!server) throw std::invalid_argument("answer_modbus: no simulated Modbus device '" + device + "'");
    return server->serve_until(client_fd, requests, deadline_ns);
}

int SimLab::take_manikin_fd() {
    const int fd = host_fd_;
    host_fd_ = -1;
    return fd;
}

SimEndpoints SimLab::endpoints() const {
    SimEndpoints e;
    e.chamber_port = chamber_->port();
    e.chamber_units = chamber_->unit_ids();
    e.datalogger_port = datalogger_->port();
    e.datalogger_units = datalogger_->unit_ids();
    e.windsonic_path = windsonic_->pty->link_path().string();
    e.csat3b_path = csat3b_->pty->link_path().string();
    e.windsonic_pty = windsonic_->pty->slave_path();
    e.csat3b_pty = csat3b_->pty->slave_path();
    return e;
}

double SimLab::time_s() const {
    std::lock_guard lk(world_lock_);
    return world_.time_s();
}

// Chamber registers by name: process values and setpoints of temperature (unit 1) and humidity
// (unit 2). Registers the world does not model (alarm thresholds) behave as plain memory.
std::vector<ServedRegister> SimLab::bind_chamber(const std::vector<RegisterDef>& defs) {
    std::vector<ServedRegister> out;
    for (const auto& d : defs) {
        ServedRegister r{d.spec, d.unit_id, d.probe, {}, {}};
        const std::string& n = d.spec.name;
        const bool rh = n.rfind("air_rh", 0) == 0;
        if (n.find("_pv_") != std::string::npos) {
            r.read = [this, rh] { return rh ? world_.chamber_rh_pct() : world_.chamber_air_temp_c(); };
        } else if (n.find("setpoint") != std::string::npos) {
            r.read = [this, rh] { return rh ? world_.chamber_rh_setpoint_pct() : world_.chamber_temp_setpoint_c(); };
            if (d.spec.writable)
                r.write = [this, rh](double v) {
                    if (rh) world_.set_chamber_setpoints(world_.chamber_temp_setpoint_c(), v);
                    else world_.set_chamber_setpoints(v, world_.chamber_rh_setpoint_pct());
                    return true;
                };
        } else {
            controller_memory_[n] = 0.0;
            r.read = [this, n] { return controller_memory_[n]; };
            if (d.spec.writable) r.write = [this, n](double v) { controller_memory_[n] = v; return true; };
        }
        out.push_back(std::move(r));
    }
    return out;
}

// Datalogger registers by name: ee181_<k>.air_temp_c / .air_rh_pct, wall_tc_<k>.wall_temp_c.
std::vector<ServedRegister> SimLab::bind_datalogger(const std::vector<RegisterDef>& defs) {
    std::vector<ServedRegister> out;
    for (const auto& d : defs) {
        ServedRegister r{d.spec, d.unit_id, d.probe, {}, {}};
        const std::string& n = d.spec.name;
        const auto dot = n.find('.');
        const auto us = n.rfind('_', dot);
        int k = 1;
        if (dot != std::string::npos && us != std::string::npos) k = std::max(1, std::atoi(n.substr(us + 1, dot - us - 1).c_str()));
        if (n.find("air_temp_c") != std::string::npos) r.read = [this, k] { return world_.measure_air_temp_c(k); };
        else if (n.find("air_rh_pct") != std::string::npos) r.read = [this, k] { return world_.measure_rh_pct(k); };
        else if (n.find("wall_temp_c") != std::string::npos) r.read = [this, k] { return world_.measure_wall_temp_c(k); };
        else r.read = [] { return 0.0; };
        out.push_back(std::move(r));
    }
    return out;
}

bool SimLab::set_room(const std::vector<physics::twin::LocalEnvironment>& room) {
    std::lock_guard lk(world_lock_);
    return world_.set_room(room);
}

bool SimLab::dress(const std::string& ensemble) {
    std::lock_guard lk(world_lock_);
    if (ensemble.empty() || ensemble == "nude") {
        world_.wear({});
        return true;
    }
    const auto e = wardrobe_ensemble(ensemble);
    world_.wear(e ? e->garments : std::vector<physics::twin::Term>{});
    return e.has_value();
}

void SimLab::inject(const FaultSpec& f) {
    {
        std::lock_guard lk(world_lock_);
        if (f.start_s > world_.time_s()) {
            scheduled_.push_back(f);
            return;
        }
        if (f.fault == "hang_up") {  // an event, not a state
            (f.device == "windsonic" ? *windsonic_ : *csat3b_).pty->hang_up_and_reopen();
            return;
        }
        active_.push_back(f);
        const int zone = static_cast<int>(f.value);
        if (f.device == "manikin" && f.fault == "heater_fail") world_.fail_heater(zone, true);
        if (f.device == "manikin" && f.fault == "stuck" && zone >= 1 && zone <= world_.zone_count())
            stuck_skin_[zone] = world_.zone(zone).skin_temp_c;
        if (f.device == "manikin" && f.fault == "bus_off") {
            can_frame err{};
            err.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;
            err.can_dlc = CAN_ERR_DLC;
            [[maybe_unused]] auto n = ::send(manikin_fd_, &err, sizeof err, MSG_DONTWAIT);
        }
    }
    update_modbus_faults();  // takes the world lock itself (stuck freezes current values)
}

void SimLab::clear_faults(const std::string& device) {
    {
        std::lock_guard lk(world_lock_);
        for (const auto& f : active_)
            if (f.device == device && f.device == "manikin" && f.fault == "heater_fail")
                world_.fail_heater(static_cast<int>(f.value), false);
        std::erase_if(active_, [&](const FaultSpec& f) { return f.device == device; });
        if (device == "manikin") stuck_skin_.clear();
    }
    update_modbus_faults();
}

std::vector<std::string> SimLab::active_faults() const {
    std::lock_guard lk(world_lock_);
    std::vector<std::string> out;
    for (const auto& f : active_) out.push_back(f.text.empty() ? f.device + ":" + f.fault : f.text);
    return out;
}

bool SimLab::fault_active(const std::string& device, const std::string& fault) const {
    return std::any_of(active_.begin(), active_.end(),
                       [&](const FaultSpec& f) { return f.device == device && f.fault == fault; });
}

double SimLab::fault_value(const std::string& device, const std::string& fault) const {
    for (const auto& f : active_)
        if (f.device == device && f.fault == fault) return f.value;
    return 0.0;
}

void SimLab::update_modbus_faults() {
    std::vector<FaultSpec> active;
    {
        std::lock_guard lk(world_lock_);
        active = active_;
    }
    for (auto* server : {chamber_.get(), datalogger_.get()}) {
        ModbusFaults m;
        for (const auto& f : active) {
            if (f.device != server->name()) continue;
            m.silent |= f.fault == "silent";
            m.exception |= f.fault == "exception";
            m.drop |= f.fault == "drop";
            m.stuck |= f.fault == "stuck";
        }
        server->set_faults(m);
    }
}

// Faults whose time has come start; those whose end has passed clear. Called under the lock.
void SimLab::apply_schedule() {
    const double now = world_.time_s();
    std::vector<FaultSpec> starting;
    std::erase_if(scheduled_, [&](const FaultSpec& f) {
        if (f.start_s > now) return false;
        starting.push_back(f);
        return true;
    });
    bool ended = false;
    std::erase_if(active_, [&](const FaultSpec& f) {
        if (f.end_s < 0 || f.end_s > now) return false;
        if (f.device == "manikin" && f.fault == "heater_fail") world_.fail_heater(static_cast<int>(f.value), false);
        if (f.device == "manikin" && f.fault == "stuck") stuck_skin_.erase(static_cast<int>(f.value));
        ended = true;
        return true;
    });
    if (starting.empty() && !ended) return;
    world_lock_.unlock();
    for (auto f : starting) {
        f.start_s = -1.0;
        inject(f);
    }
    update_modbus_faults();
    world_lock_.lock();
}

void SimLab::step(double dt_s) {
    std::unique_lock lk(world_lock_);
    // What the host sent since the last step, on the bus and on the two serial lines: one poll
    // instead of a read on each that mostly answers EAGAIN (3 system calls a step, 1 now).
    std::array<pollfd, 3> ready{{{manikin_fd_, POLLIN, 0}, {windsonic_->pty->fd(), POLLIN, 0}, {csat3b_->pty->fd(), POLLIN, 0}}};
    if (::poll(ready.data(), ready.size(), 0) < 0)
        for (auto& r : ready) r.revents = POLLIN;  // EINTR or the like: read each as before
    if (ready[0].revents != 0) manikin_io();  // commands the host sent act from now on
    world_.step(dt_s);
    apply_schedule();
    can_frames_last_step_ = 0;
    // Manikin bus output.
    const double now = world_.time_s();
    const bool silent = fault_active("manikin", "silent") || fault_active("manikin", "bus_off");
    // This step's frames go out together in one sendmmsg (36 frames a second: one system call
    // instead of 36), each still its own datagram, as frames on a bus are.
    std::vector<can_frame> frames;
    frames.reserve(static_cast<std::size_t>(world_.zone_count()) + 2);
    auto send = [&](const can_frame& fr) { frames.push_back(fr); };
    // The heartbeat goes out every step (the real one every 100 ms); zone reports at their period.
    if (!silent) {
        mc::Heartbeat hb;
        hb.mode = world_.manikin_running() ? mc::ControlMode::constant_skin_temp : mc::ControlMode::idle;
        hb.sequence = heartbeat_seq_++;
        hb.error_bits = world_.watchdog_tripped() ? 1 : 0;
        hb.shell_supply_v = 24.0;
        send(mc::encode(hb));
    }
    if (now + 1e-9 >= manikin_due_s_) {
        manikin_due_s_ = now + o_.manikin_period_s;
        if (!silent) {
            for (int z = 1; z <= world_.zone_count(); ++z) {
                mc::ZoneStatus st = world_.measure_zone(z);
                if (const auto it = stuck_skin_.find(z); it != stuck_skin_.end()) st.skin_temp_c = it->second;
                send(mc::encode(st));
            }
        }
        if (fault_active("manikin", "error_frames")) {
            can_frame err{};
            err.can_id = CAN_ERR_FLAG | CAN_ERR_CRTL;
            err.can_dlc = CAN_ERR_DLC;
            err.data[1] = CAN_ERR_CRTL_RX_WARNING;
            send(err);
        }
    }
    if (!frames.empty()) {
        std::vector<iovec> iov(frames.size());
        std::vector<mmsghdr> msgs(frames.size());
        for (std::size_t i = 0; i < frames.size(); ++i) {
            iov[i] = {&frames[i], sizeof(can_frame)};
            msgs[i] = {};
            msgs[i].msg_hdr.msg_iov = &iov[i];
            msgs[i].msg_hdr.msg_iovlen = 1;
        }
        const int sent = ::sendmmsg(manikin_fd_, msgs.data(), static_cast<unsigned>(msgs.size()), MSG_DONTWAIT);
        // A full socket buffer (the host not reading) drops the rest, as a bus would for a dead node.
        if (sent > 0) can_frames_last_step_ += sent;
    }
    serial_output(*windsonic_, ready[1].revents != 0);
    serial_output(*csat3b_, ready[2].revents != 0);
}

void SimLab::manikin_io() {
    can_frame fr{};
    for (;;) {
        const ssize_t n = ::recv(manikin_fd_, &fr, sizeof fr, MSG_DONTWAIT);
        if (n != static_cast<ssize_t>(sizeof fr)) break;
        if (fault_active("manikin", "bus_off")) continue;
        const auto decoded = mc::decode(fr);
        if (const auto* msg = std::get_if<mc::Message>(&decoded)) {
            if (const auto* sp = std::get_if<mc::Setpoint>(msg)) world_.manikin_command(*sp);
            else if (const auto* c = std::get_if<mc::Control>(msg)) world_.manikin_control(c->run);
        }
    }
}

// Called under the world lock.
void SimLab::serial_output(SerialDevice& d, bool host_sent) {
    d.bytes_last_step = 0;
    // Polled mode: a node letter asks for a frame (read only when the poll says it came).
    const std::string host = host_sent ? d.pty->read_available() : std::string();
    const bool polled_request = !host.empty();
    const double now = world_.time_s();
    if (!(now + 1e-9 >= d.due_s) && !polled_request) return;
    if (now + 1e-9 >= d.due_s) d.due_s = now + d.period_s;
    if (fault_active(d.name, "silent")) return;
    std::string line;
    if (fault_active(d.name, "stuck") && !d.last_line.empty()) {
        line = d.last_line;
    } else if (d.name == "windsonic") {
        protocol::windsonic::Reading r;
        r.speed = std::round(world_.measure_air_speed_m_s() * 100.0) / 100.0;  // 0.01 m/s resolution
        r.direction_deg = r.speed >= 0.05 ? std::optional<int>(static_cast<int>(rng_() % 360)) : std::nullopt;
        r.status = fault_active(d.name, "status") ? static_cast<int>(fault_value(d.name, "status")) : 0;
        line = protocol::windsonic::encode_frame(r);
        if (fault_active(d.name, "bad_checksum")) {
            const auto pos = line.find('\x03') + 1;  // first checksum digit
            line[pos] = line[pos] == '0' ? '1' : '0';
        }
    } else {
        protocol::csat3b::Record r;
        const double speed = world_.measure_air_speed_m_s();
        const double angle = static_cast<double>(rng_() % 6283) / 1000.0;
        r.ux_m_s = speed * std::cos(angle);
        r.uy_m_s = speed * std::sin(angle);
        r.uz_m_s = 0.1 * speed * std::sin(3.0 * angle);
        r.sonic_temp_c = world_.enclosure_air_temp_c() + 0.4;  // virtual temperature reads a little high
        r.diag = fault_active(d.name, "status") ? static_cast<std::uint32_t>(fault_value(d.name, "status")) : 0u;
        r.counter = d.counter++ % 64;
        line = protocol::csat3b::encode_line(r);
        if (fault_active(d.name, "bad_checksum")) {
            const auto pos = line.rfind(',') + 1;  // first signature digit
            line[pos] = line[pos] == '0' ? '1' : '0';
        }
    }
    d.last_line = line;
    if (fault_active(d.name, "garbage")) {
        std::string junk(12, '\0');
        for (auto& c : junk) c = static_cast<char>(rng_() % 256);
        line = junk + line;
    }
    d.bytes_last_step = d.pty->write(line);
}

std::uint64_t SimLab::serial_bytes_last_step(const std::string& device) const {
    std::lock_guard lk(world_lock_);
    return device == "windsonic" ? windsonic_->bytes_last_step : csat3b_->bytes_last_step;
}

}  // namespace manikind::sim
