// `manikin sim serve`: the simulated lab alone, for third-party clients (SCADA, LabVIEW, mbpoll,
// a terminal, candump-style tools): prints every endpoint and runs until SIGINT/SIGTERM.
// `manikin replay <candump.log>`: feeds a captured manikin bus log back through the driver.
#include <poll.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <linux/can.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "daemon/simulated_lab.hpp"
#include "daemon/config.hpp"
#include "store/database.hpp"
#include "drivers/register_map.hpp"
#include "base/user_error.hpp"
#include "drivers/anemometers.hpp"
#include "drivers/modbus_driver.hpp"
#include "drivers/manikin_can_driver.hpp"
#include "physics/sign_convention.hpp"
#include "protocol/manikin_can.hpp"

namespace manikind::cli {

namespace {

struct ServeOptions {
    std::string config_path;
    double speed = 1.0;
    std::vector<std::string> faults;
    bool json = false;
    bool realtime = false;
    int chamber_port = 0, datalogger_port = 0;
    std::string runtime_dir;
};

void serve(const ServeOptions& o) {
    config::Config cfg = o.config_path.empty() ? config::default_config() : config::load_config(o.config_path);
    if (!o.runtime_dir.empty()) cfg.simulation.runtime_dir = o.runtime_dir;
    for (const auto& f : o.faults) cfg.simulation.faults.push_back(f);
    sim::SimLabOptions lab_options = simulated_lab_options(cfg);
    lab_options.chamber_port = o.chamber_port;
    lab_options.datalogger_port = o.datalogger_port;
    lab_options.manikin_period_s = 1.0;
    const std::filesystem::path runtime = lab_options.runtime_dir;
    sim::SimLab lab(lab_options);
    const int lab_bus = lab.take_manikin_fd();

    // The manikin bus for outside clients: a SOCK_SEQPACKET Unix socket carrying struct can_frame,
    // bridged to the lab's end of the bus (one client at a time).
    const std::string bus_path = (runtime / "manikin-bus.sock").string();
    const int listen_fd = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", bus_path.c_str());
    ::unlink(bus_path.c_str());
    if (::bind(listen_fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(listen_fd, 1) != 0)
        throw UserError(fmt::format("cannot listen on {}: {}", bus_path, std::strerror(errno)));

    const auto ep = lab.endpoints();
    nlohmann::json j = {
        {"chamber", {{"protocol", "modbus-tcp"}, {"host", ep.chamber_host}, {"port", ep.chamber_port}, {"units", ep.chamber_units},
                     {"register_map", "config/chamber_registers.toml"}}},
        {"datalogger", {{"protocol", "modbus-tcp"}, {"host", ep.chamber_host}, {"port", ep.datalogger_port},
                        {"units", ep.datalogger_units}, {"register_map", "config/datalogger_registers.toml"}}},
        {"windsonic", {{"protocol", "Gill ASCII, 9600 8N1"}, {"path", ep.windsonic_path}, {"pty", ep.windsonic_pty}}},
        {"csat3b", {{"protocol", "Campbell CSAT3B ASCII"}, {"path", ep.csat3b_path}, {"pty", ep.csat3b_pty}}},
        {"manikin", {{"protocol", "struct can_frame over SOCK_SEQPACKET (docs/manikin-can-bus.md)"}, {"path", bus_path}}},
        {"speed", o.speed},
        {"faults", cfg.simulation.faults}};
    if (o.json) {
        std::printf("%s\n", j.dump().c_str());
    } else {
        std::printf("simulated lab serving (speed %gx; Ctrl-C stops):\n", o.speed);
        std::printf("  chamber controller  modbus-tcp 127.0.0.1:%d  units %s (1 temperature, 2 humidity)\n", ep.chamber_port,
                    j["chamber"]["units"].dump().c_str());
        std::printf("  datalogger          modbus-tcp 127.0.0.1:%d  unit %s (EE181 mV, thermocouples 0.01 °C)\n",
                    ep.datalogger_port, j["datalogger"]["units"].dump().c_str());
        std::printf("  WindSonic           %s  (-> %s)\n", ep.windsonic_path.c_str(), ep.windsonic_pty.c_str());
        std::printf("  CSAT3B              %s  (-> %s)\n", ep.csat3b_path.c_str(), ep.csat3b_pty.c_str());
        std::printf("  manikin bus         %s  (SOCK_SEQPACKET, struct can_frame)\n", bus_path.c_str());
        std::printf("  try: mbpoll -m tcp -p %d -a 1 -r 2 -c 1 -1 127.0.0.1   (chamber temperature PV, x10)\n", ep.chamber_port);
    }
    std::fflush(stdout);

    sigset_t mask;
    sigemptyset(&mask);
    sigaddset(&mask, SIGINT);
    sigaddset(&mask, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &mask, nullptr);
    const int sig_fd = signalfd(-1, &mask, SFD_CLOEXEC);
    int client = -1;
    const double tick_s = 0.1;
    auto next = std::chrono::steady_clock::now();
    for (;;) {
        next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(tick_s));
        // Wait for the next tick, a signal, a client, or frames in either direction.
        for (;;) {
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(next - std::chrono::steady_clock::now());
            if (left.count() <= 0) break;
            std::vector<pollfd> fds = {{sig_fd, POLLIN, 0}, {listen_fd, POLLIN, 0}, {lab_bus, POLLIN, 0}};
            if (client >= 0) fds.push_back({client, POLLIN, 0});
            ::poll(fds.data(), fds.size(), static_cast<int>(left.count()));
            if (fds[0].revents) {
                if (!o.json) std::printf("simulated lab: stopping\n");
                if (client >= 0) ::close(client);
                ::close(listen_fd);
                ::unlink(bus_path.c_str());
                ::close(lab_bus);
                return;
            }
            if (fds[1].revents & POLLIN) {
                const int c = ::accept4(listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
                if (c >= 0) {
                    if (client >= 0) ::close(client);
                    client = c;
                }
            }
            can_frame fr{};
            if (fds[2].revents & POLLIN)
                while (::recv(lab_bus, &fr, sizeof fr, MSG_DONTWAIT) == static_cast<ssize_t>(sizeof fr))
                    if (client >= 0) ::send(client, &fr, sizeof fr, MSG_DONTWAIT | MSG_NOSIGNAL);
            if (client >= 0 && fds.size() > 3 && fds[3].revents) {
                const ssize_t n = ::recv(client, &fr, sizeof fr, MSG_DONTWAIT);
                if (n == static_cast<ssize_t>(sizeof fr)) ::send(lab_bus, &fr, sizeof fr, MSG_DONTWAIT);
                else if (n == 0) {
                    ::close(client);
                    client = -1;
                }
            }
        }
        lab.step(tick_s * o.speed);
    }
}

struct ReplayOptions {
    std::string file;
    bool json = false;
    std::string db, campaign;
};

struct CapturedFrame {
    std::int64_t t_ns = 0;  // the candump stamp, UTC
    can_frame frame{};
    int line = 0;
};

struct Capture {
    std::vector<CapturedFrame> frames;  // in time order, identical duplicates left out
    std::size_t duplicates = 0;
};

bool same_frame(const can_frame& a, const can_frame& b) {
    return a.can_id == b.can_id && a.can_dlc == b.can_dlc && std::memcmp(a.data, b.data, a.can_dlc) == 0;
}

// Reads a `candump -l` capture and checks every line: a candump line with a good stamp
// (protocol's parse_candump_log_line), never before the previous one. A frame identical to one already seen at
// the same stamp (a logger writing a frame twice) is skipped and counted.
Capture read_capture(const std::string& file) {
    std::error_code ec;
    if (std::filesystem::exists(file, ec) && !std::filesystem::is_regular_file(file, ec))
        throw UserError(fmt::format("{}: not a regular file", file));
    std::ifstream in(file);
    if (!in) throw UserError(fmt::format("{}: cannot open the capture", file));
    Capture capture;
    std::string text;
    int line_no = 0, previous_line = 0;
    while (std::getline(in, text)) {
        ++line_no;
        if (text.empty() || text[0] == '#') continue;
        const auto parsed = protocol::manikin_can::parse_candump_log_line(text);
        if (!parsed.ok()) throw UserError(fmt::format("{}:{}: {}", file, line_no, parsed.error));
        const std::int64_t t_ns = parsed.utc_ns;
        if (!capture.frames.empty() && t_ns < capture.frames.back().t_ns)
            throw UserError(fmt::format("{}:{}: time stamp {:.6f} s is before {:.6f} s on line {}; a capture must be in time order",
                                        file, line_no, static_cast<double>(t_ns) * 1e-9,
                                        static_cast<double>(capture.frames.back().t_ns) * 1e-9, previous_line));
        // Earlier frames with this stamp sit at the back, the capture being in time order.
        bool duplicate = false;
        for (auto it = capture.frames.rbegin(); it != capture.frames.rend() && it->t_ns == t_ns && !duplicate; ++it)
            duplicate = same_frame(it->frame, parsed.frame);
        previous_line = line_no;
        if (duplicate) {
            ++capture.duplicates;
            continue;
        }
        capture.frames.push_back({t_ns, parsed.frame, line_no});
    }
    if (capture.frames.empty()) throw UserError(fmt::format("{}: no frames", file));
    return capture;
}

// Records a checked replay as one campaign, one case, one trial holding the whole capture.
void store_replay(const ReplayOptions& r, const std::vector<drivers::Sample>& samples, std::int64_t end_utc_ns) {
    auto db = recorder::Database::open(r.db);
    const std::string name = r.campaign.empty() ? "replay-" + std::filesystem::path(r.file).filename().string() : r.campaign;
    const auto campaign = db.create_campaign(name, nlohmann::json{{"replayed_from", r.file}}.dump());
    const std::int64_t trial_id = db.create_trial(campaign, db.add_case(campaign, "replay", "{}", 0), 1);
    db.set_trial_state(trial_id, "acquiring", "replay of " + r.file, 0);
    const std::int64_t device_id = db.device_id("manikin", "can", "replay " + r.file);
    std::map<std::string, std::int64_t> channel_ids;
    std::vector<recorder::SampleRow> rows;
    for (const auto& sample : samples) {
        auto it = channel_ids.find(sample.channel);
        if (it == channel_ids.end())
            it = channel_ids.emplace(sample.channel, db.channel_id(device_id, sample.channel, drivers::unit_of_channel(sample.channel)))
                     .first;
        rows.push_back({trial_id, it->second, sample.mono_ns, sample.utc_ns, sample.value, static_cast<std::uint8_t>(sample.quality)});
    }
    // Every (channel, time) is unique by now, so every row is stored.
    db.insert_samples(rows);
    db.set_trial_state(trial_id, "done", "replayed", end_utc_ns);
}

}  // namespace

void add_sim_commands(CLI::App& app) {
    auto* simcmd = app.add_subcommand("sim", "The simulated lab on its own");
    simcmd->require_subcommand(1);
    auto o = std::make_shared<ServeOptions>();
    auto* srv = simcmd->add_subcommand("serve", "Run the simulated lab alone and print every endpoint a third-party client needs");
    srv->add_option("--config", o->config_path, "Configuration (default: the built-in simulated lab)");
    auto* rt = srv->add_flag("--realtime", o->realtime, "Run at the wall clock's pace (the default)");
    srv->add_option("--speed", o->speed, "Run this many times faster than the wall clock")->check(CLI::Range(0.1, 100.0))->excludes(rt);
    srv->add_option("--fault", o->faults, "Inject a fault: device:fault[=value][@start_s[-end_s]] (repeatable)");
    srv->add_option("--chamber-port", o->chamber_port, "Chamber Modbus TCP port on 127.0.0.1 (default: any free port)");
    srv->add_option("--datalogger-port", o->datalogger_port, "Datalogger Modbus TCP port on 127.0.0.1 (default: any free port)");
    srv->add_option("--runtime-dir", o->runtime_dir, "Where the pty links and the manikin bus socket go");
    srv->add_flag("--json", o->json, "Print the endpoints as one JSON line");
    srv->footer(std::string("Faults:\n") + sim::fault_help());
    srv->callback([o] { serve(*o); });

    auto r = std::make_shared<ReplayOptions>();
    auto* rep = app.add_subcommand("replay", "Feed a manikin bus capture (can-utils `candump -l` format) through the driver");
    rep->add_option("file", r->file, "candump -l log: (1718000000.123456) can0 123#11223344")->required();
    rep->add_flag("--json", r->json, "Print the last value of every channel as JSON");
    rep->add_option("--db", r->db, "Also record the replayed samples into this database (a trial of --campaign)");
    rep->add_option("--campaign", r->campaign, "Campaign name for the replayed trial (default: replay-<file name>)");
    rep->footer(std::string("Heat flux: ") + physics::heat_flux_sign + " (docs/manikin-can-bus.md).");
    rep->callback([r] {
        // Everything is read and checked first, then replayed; only then is anything stored,
        // so a bad capture leaves the database as it was.
        const Capture capture = read_capture(r->file);
        const std::int64_t t0 = capture.frames.front().t_ns;
        drivers::ManualClock clock(t0);  // replay time is the capture's own: UTC of the first frame
        std::map<std::string, drivers::Sample> last;
        std::map<std::string, int> last_line;  // the line of each channel's last sample, for messages
        std::vector<drivers::Sample> samples;
        int line = 0;
        boost::asio::io_context io;
        drivers::ManikinCanDriver driver(io, -1, {}, clock, [&](const drivers::Sample& sample) {
            // Two different frames at one time stamp giving the same channel: the database keeps
            // one sample per channel and time, so which one is right cannot be decided here.
            if (const auto it = last.find(sample.channel); it != last.end() && it->second.mono_ns == sample.mono_ns)
                throw UserError(fmt::format("{}:{}: a second reading of {} at the time stamp of line {}", r->file, line,
                                            sample.channel, last_line[sample.channel]));
            last[sample.channel] = sample;
            last_line[sample.channel] = line;
            samples.push_back(sample);
        });
        for (const auto& f : capture.frames) {
            line = f.line;
            clock.advance_ns(f.t_ns - t0 - clock.mono_ns());
            driver.ingest(f.frame);
        }
        const std::size_t frames = capture.frames.size();
        const auto st = driver.status();
        if (!r->db.empty()) store_replay(*r, samples, clock.utc_ns());
        if (r->json) {
            nlohmann::json j = {{"frames", frames},
                                {"duplicate_frames", capture.duplicates},
                                {"samples", samples.size()},
                                {"malformed", st.malformed},
                                {"channels", nlohmann::json::object()}};
            for (const auto& [ch, v] : last) j["channels"][ch] = {{"value", v.value}, {"quality", drivers::to_string(v.quality)}};
            std::printf("%s\n", j.dump(2).c_str());
            return;
        }
        std::printf("%s: %zu frames, %zu identical duplicates skipped, %zu samples%s, %llu malformed, %.1f s of bus time\n",
                    r->file.c_str(), frames, capture.duplicates, samples.size(), r->db.empty() ? "" : " stored",
                    static_cast<unsigned long long>(st.malformed), clock.elapsed_s());
        for (const auto& [ch, v] : last) std::printf("  %-24s %10.2f  %s\n", ch.c_str(), v.value, drivers::to_string(v.quality));
    });
}

}  // namespace manikind::cli

namespace manikind::cli {

// `manikin probe`: talk to one instrument directly with our driver (bring-up, and the peer tests).
void add_probe_command(CLI::App& app) {
    struct ProbeOptions {
        std::string device, path, host = "127.0.0.1", map = "builtin";
        int port = 502;
        int max_gap_registers = static_cast<int>(config::ModbusDeviceConfig{}.max_gap_registers);
        int requests_in_flight = 1;
        std::size_t count = 10;
        double timeout_s = 5.0;
        std::vector<std::string> writes, reads;
        bool json = false;
    };
    auto o = std::make_shared<ProbeOptions>();
    auto* cmd = app.add_subcommand("probe", "Talk to one instrument with our driver: read frames or registers, write a setpoint");
    cmd->add_option("device", o->device, "windsonic | csat3b | chamber | datalogger")
        ->check(CLI::IsMember({"windsonic", "csat3b", "chamber", "datalogger"}))
        ->required();
    cmd->add_option("path", o->path, "Serial device (windsonic, csat3b)");
    cmd->add_option("--host", o->host, "Modbus TCP host")->capture_default_str();
    cmd->add_option("--port", o->port, "Modbus TCP port")->capture_default_str();
    cmd->add_option("--map", o->map, "Register map: builtin or a TOML file")->capture_default_str();
    cmd->add_option("--max-gap", o->max_gap_registers,
                    "Modbus: read across up to this many unused registers in one request (0: contiguous runs only)")
        ->check(CLI::Range(0, 124))
        ->capture_default_str();
    cmd->add_option("--in-flight", o->requests_in_flight,
                    "Modbus TCP: send up to this many requests of a poll before reading their replies")
        ->check(CLI::Range(1, 16))
        ->capture_default_str();
    cmd->add_option("--count", o->count, "Serial: stop after this many samples of the speed channel")->capture_default_str();
    cmd->add_option("--timeout", o->timeout_s, "Give up after this many seconds")->capture_default_str();
    cmd->add_option("--write", o->writes, "Modbus: write name=value (checked against the map's limits)");
    cmd->add_option("--read", o->reads, "Modbus: read this register (default: every polled one)");
    cmd->add_flag("--json", o->json, "One JSON document");
    cmd->footer("A --write beyond the register map's limits is refused: exit status 4; under --json the readings are\n"
                "then the error's \"details\" (docs/cli.md).");
    cmd->callback([o] {
        drivers::SystemClock clock;
        nlohmann::json out = {{"device", o->device}, {"samples", nlohmann::json::array()}};
        auto sample_json = [](const drivers::Sample& s) {
            return nlohmann::json{{"channel", s.channel},
                                  {"value", std::isfinite(s.value) ? nlohmann::json(s.value) : nlohmann::json(nullptr)},
                                  {"quality", drivers::to_string(s.quality)}};
        };
        auto status_json = [](const drivers::DriverStatus& st) {
            return nlohmann::json{{"frames", st.frames}, {"samples", st.samples}, {"checksum_errors", st.checksum_errors},
                                  {"malformed", st.malformed}, {"timeouts", st.timeouts}, {"exceptions", st.exceptions},
                                  {"reconnects", st.reconnects}, {"comm_errors", st.comm_errors},
                                  {"device_faults", st.device_faults}, {"last_error", st.last_error}};
        };
        if (o->device == "windsonic" || o->device == "csat3b") {
            if (o->path.empty()) throw UserError("give the serial device path");
            boost::asio::io_context io;
            std::size_t speeds = 0;
            auto sink = [&](const drivers::Sample& s) {
                out["samples"].push_back(sample_json(s));
                if (s.channel == "air_speed_m_s") ++speeds;
            };
            drivers::SerialOptions so{o->device, o->path, o->device == "windsonic" ? 9600u : 115200u, o->timeout_s};
            std::unique_ptr<drivers::SerialLineDriver> d;
            if (o->device == "windsonic") d = std::make_unique<drivers::WindSonicDriver>(io, so, clock, sink);
            else d = std::make_unique<drivers::Csat3bDriver>(io, so, clock, sink);
            d->start();
            if (!d->status().connected) throw UserError(d->status().last_error);
            std::fprintf(stderr, "probe: reading %s\n", o->path.c_str());  // peers wait for this line
            std::fflush(stderr);
            const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(o->timeout_s);
            while (speeds < o->count && std::chrono::steady_clock::now() < deadline) io.run_one_for(std::chrono::milliseconds(100));
            out["status"] = status_json(d->status());
            d->stop();
        } else {
            config::Config cfg = config::default_config();
            drivers::ModbusOptions mo;
            mo.device_name = o->device;
            mo.host = o->host;
            mo.port = o->port;
            mo.response_timeout_s = std::min(o->timeout_s, 2.0);
            mo.max_gap_registers = o->max_gap_registers;
            mo.requests_in_flight = o->requests_in_flight;
            mo.points = modbus_points(register_map_from_setting(o->map, o->device, {}));
            drivers::ModbusDriver d(mo, clock, [&](const drivers::Sample& s) { out["samples"].push_back(sample_json(s)); });
            d.start();
            out["writes"] = nlohmann::json::array();
            for (const auto& w : o->writes) {
                const auto eq = w.find('=');
                const std::string value_text = eq == std::string::npos ? "" : w.substr(eq + 1);
                char* end = nullptr;
                const double value = std::strtod(value_text.c_str(), &end);
                if (eq == std::string::npos || value_text.empty() || *end != '\0')
                    throw UserError("--write: expected name=value with a number, got " + w);
                const std::string why = d.write(w.substr(0, eq), value);
                out["writes"].push_back({{"register", w.substr(0, eq)}, {"ok", why.empty()}, {"error", why}});
            }
            if (o->reads.empty()) {
                d.poll();
            } else {
                for (const auto& r : o->reads) {
                    const auto v = d.read(r);
                    out["samples"].push_back({{"channel", r}, {"value", v ? nlohmann::json(*v) : nlohmann::json(nullptr)},
                                              {"quality", v ? "good" : "comm_error"}});
                }
            }
            out["status"] = status_json(d.status());
        }
        // A write the map's limits refused is a refusal (status 4), after the readings are shown.
        std::string refused;
        if (out.contains("writes"))
            for (const auto& w : out["writes"])
                if (!w["ok"].get<bool>())
                    refused += fmt::format("{}write {} refused: {}", refused.empty() ? "" : "; ", w["register"].get<std::string>(),
                                           w["error"].get<std::string>());
        if (o->json) {
            if (!refused.empty()) throw UserError::refused(refused, out);
            std::printf("%s\n", out.dump(2).c_str());
            return;
        }
        for (const auto& s : out["samples"])
            std::printf("%-28s %12s  %s\n", s["channel"].get<std::string>().c_str(), s["value"].dump().c_str(),
                        s["quality"].get<std::string>().c_str());
        std::printf("%s\n", out["status"].dump().c_str());
        if (!refused.empty()) throw UserError::refused(refused);
    });
}

}  // namespace manikind::cli
