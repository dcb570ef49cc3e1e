#pragma once
// The daemon's configuration, read from TOML. Every error names the file, the line and
// column, and the key (`config/manikind.toml:12:1: safety.max_skin_temp_c: expected a number,
// found a string`). Unknown keys are warnings (a typo must not silently drop a limit, but an
// extra note in a lab's file must not stop a trial either).
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "analysis/zone_map.hpp"
#include "sim/campaign/replicate_scatter.hpp"

namespace manikind::config {

struct InstrumentSpec {
    double accuracy = 0.0;             // in the channel's unit
    double accuracy_of_reading = 0.0;  // fraction of |reading|
    std::string distribution = "rectangular";
};

struct SafetyLimits {
    double max_skin_temp_c = 45.0;         // manikin surface setpoint ceiling
    double min_skin_temp_c = 20.0;
    double max_heater_temp_c = 50.0;
    double max_heater_power_w_m2 = 650.0;  // at or above the heaters' rating: a reading the hardware cannot make
    double min_chamber_temp_c = 5.0;
    double max_chamber_temp_c = 55.0;
    double min_chamber_rh_pct = 5.0;
    double max_chamber_rh_pct = 95.0;
    double watchdog_timeout_s = 10.0;      // silence after which heating stops
};

struct SteadyStateRule {
    double window_s = 1800.0;              // Methods: the final 30 min
    double max_skin_fluctuation_c = 0.05;  // Methods: < 0.05 °C
};

// Where each instrument is. "builtin" register maps are the shipped config/*_registers.toml.
struct ModbusDeviceConfig {
    std::string host = "127.0.0.1";
    double port = 502;
    std::string serial;              // RTU device path; overrides host/port when set
    double baud = 19200;
    std::string register_map = "builtin";
    // Read across a hole of up to this many unused registers rather than send another request
    // (docs/devices.md, "Modbus block reads"). A device that refuses a range with a hole ("illegal
    // data address") is then read in its contiguous runs; 0 reads contiguous runs only.
    double max_gap_registers = 16;
    // Modbus TCP: how many requests of one poll go out before their replies are read (the
    // Messaging on TCP/IP guide allows several; many gateways take one at a time). The simulated
    // lab's devices take every request of a poll at once, whatever is set here.
    double requests_in_flight = 1;
};

struct DeviceConfig {
    ModbusDeviceConfig chamber;
    ModbusDeviceConfig datalogger;
    std::string windsonic_path = "/dev/ttyUSB0";
    double windsonic_baud = 9600;    // WindSonic default (manual section 9)
    std::string csat3b_path = "/dev/ttyUSB1";
    double csat3b_baud = 115200;     // CSAT3B RS-485/USB default
    std::string manikin_interface = "can0";
    std::string manikin_capture;     // record every bus frame to this candump -l log (empty: off)
    // [devices.manikin] max_heater_power_w_m2: the heaters' rated output, which every cold start
    // reaches (the zone loop saturates). [safety] max_heater_power_w_m2 below it would trip on
    // every start, so config check refuses that. The simulated manikin's heaters saturate here.
    double manikin_max_heater_power_w_m2 = 600.0;
    double modbus_timeout_s = 0.5;
    double poll_period_s = 1.0;
    double stale_after_s = 3.0;
};

// The simulated lab (mode = "simulated"): what the world does that the twin may not know.
// [[simulation.local]]: where the simulated room is not uniform (docs/comfort.md, "A non-uniform
// room"). Entries add up on a zone they share; the last air speed named for a zone holds.
struct LocalEnvironmentConfig {
    std::vector<std::string> zones;           // zone names, regions or segments of the zone map
    std::string what;                         // a note: "windscreen in the sun", "vent jet"
    double air_offset_c = 0.0;                // the air at these zones minus the probes' reading
    double radiant_offset_c = 0.0;            // their mean radiant temperature minus the walls'
    double air_speed_m_s = -1.0;              // the air's speed at them; < 0: the room's
    double contact_w_m2 = 0.0;                // conducted into a surface they touch (< 0: a heated seat)
    double solar_w_m2 = 0.0;                  // sun absorbed
    std::string where;                        // file:line of the entry, for errors
};

struct SimulationConfig {
    std::uint64_t seed = 1;
    std::vector<std::string> world_effects;   // physics terms, as `manikin simulate-campaign --effect`
    std::vector<std::string> faults;          // scheduled faults: device:fault[=v][@start[-end]]
    std::string runtime_dir;                  // pty links; empty: a fresh directory under /tmp
    double step_s = 1.0;                      // virtual-clock step
    double manikin_period_s = 5.0;            // the manikin's zone report interval (Text S3.2: 5 s)
    double air_speed_m_s = 0.01;              // the enclosure's air speed: sealed < 0.02 (Text S3.1); 0.4 for clothing tests
    double wall_below_air_c = 0.4;            // the enclosure's walls below its air (Text S3.3); 0 for a teq calibration's uniform room
    // Who answers an operator prompt (dress the manikin for a clothing test): "auto", the simulated
    // operator at once (campaigns run unattended: tests, the demo); "wait", `manikin continue` or
    // the console's button, as on a real lab, where prompts always wait.
    std::string operator_prompts = "auto";
    sim::ReplicateScatter scatter;            // per-trial replicate scatter (keys replicate_*, probe_*)
    std::vector<LocalEnvironmentConfig> local;  // empty: the uniform enclosure of the paper
};

struct ApiConfig {
    std::string socket = "manikind.sock";   // Unix socket, mode 0660; relative: from the working directory
    double tcp_port = 0;                     // 0: off; else listens on 127.0.0.1 only
    std::string token;                       // empty: the daemon makes one and writes <socket>.token (0600)
    double max_clients = 64;                 // simultaneous control connections (docs/daemon.md: who makes room)
    double idle_timeout_s = 120;             // a client silent this long is disconnected
    double partial_grace_s = 0.5;            // a half-written request older than this is the first to make room
    double max_clients_per_peer = 0;         // connections per process; 0: max(4, max_clients / 4)
};

// [standby]: where the chamber and manikin are put when a campaign ends (done, aborted, or by a
// safety stop) or is aborted: heating off, the chamber at a mild setpoint (checked against
// [safety]). A lab leaves the enclosure so between campaigns, not at the last case's 44 °C.
struct StandbyConfig {
    double chamber_temp_c = 23.0;
    double chamber_rh_pct = 45.0;
};

// The operator console (web page, WebSocket, /metrics): off unless `listen` is set.
struct HttpConfig {
    std::string listen;                      // "127.0.0.1:8470"; loopback addresses only; port 0: any free port
};

// [archive]: forward what the recorder commits to a lab-wide PostgreSQL archive (docs/archive.md).
// Off while `postgresql` is empty. The local database stays the source of truth: forwarding runs
// on its own thread and its own read-only connection, and acquisition never waits for it.
struct ArchiveConfig {
    std::string postgresql;   // a libpq connection string or URI; a password belongs in ~/.pgpass
    std::string lab_id;       // this lab's key in the archive: 1-64 of [A-Za-z0-9._-], the same for every push
    std::string lab_name;     // shown beside the id; empty: [lab] name
    double interval_s = 5.0;  // between forwarding passes while the server answers
};

// [notifications]: what is sent away from the screen, and where (docs/daemon.md, "Notifications").
// Off unless a webhook URL or an SMTP URL with recipients is set.
struct NotificationsConfig {
    std::vector<std::string> events{"safety", "alarm_error", "campaign_end"};  // notice_kinds()
    std::string webhook_url;            // http:// or https://
    std::string webhook_format = "json";// json (ntfy and generic), slack, matrix
    std::string smtp_url;               // smtp:// or smtps://host:port
    std::string mail_from;
    std::vector<std::string> mail_to;
    double min_interval_s = 60.0;       // per destination: what comes within is sent together
    double retries = 4;                 // after the first try
    double timeout_s = 10.0;            // per try
};

// [physiological]: the manikin under a thermoregulation model's control (docs/thermoregulation.md,
// "The manikin in the loop"). The limits are the daemon's, enforced whatever the model asks.
struct PhysiologicalConfig {
    double coupling_period_s = 20.0;          // the model advances and the setpoints are sent this often (measured: docs/thermoregulation.md)
    double max_setpoint_rate_c_min = 0.5;     // per zone, either way
    double min_skin_setpoint_c = 30.0;        // the model's skin temperatures are clamped here ([safety] still applies)
    double max_skin_setpoint_c = 40.0;
    double max_sweat_rate_g_m2_h = 500.0;     // the sweat pumps' range
    double follow_tolerance_c = 1.0;          // a zone this far off its setpoint ...
    double follow_timeout_s = 600.0;          // ... for this long cannot follow: fallback
    double stale_after_s = 30.0;              // a zone's heat flux older than this is stale: fallback
    double min_core_temp_c = 35.0;            // the model's core outside these has diverged: fallback
    double max_core_temp_c = 40.5;
    // The zones' shell: heat the heaters put into warming it is not heat the body lost, so the loop
    // feeds the model the measured flux minus C dT_skin/dt (issue 63). Per m² of zone; the
    // default is the simulated lab's shell (sim/world), with 20 % as its standard uncertainty:
    // set your manikin's (its maker's figure, or a step test: docs/thermoregulation.md).
    double shell_heat_capacity_j_m2k = 2500.0;
    double shell_heat_capacity_u_j_m2k = 500.0;
    // Which zone-map segments make each model segment (head, trunk, arms, hands, legs, feet).
    std::map<std::string, std::vector<std::string>> segments = analysis::default_model_segments();
};

struct Config {
    std::string lab_name = "simulated lab";
    std::string mode = "simulated";        // simulated | real
    std::string chamber;                   // [lab] chamber: make, model, serial number (recorded with each trial)
    std::string manikin;                   // [lab] manikin: likewise
    std::string log_level = "info";
    std::filesystem::path database = "manikind.db";
    double idle_log_period_s = 10.0;       // outside trials, one reading per channel this often (0: off)
    // [recorder] durability: "process" survives a killed daemon (SQLite synchronous = NORMAL);
    // "power" also a power cut (FULL: every commit synced to the disk). docs/recorder.md.
    std::string recorder_durability = "process";
    // [recorder] commit_interval_s: the longest a row waits for its commit. 30 s: near WAL's floor
    // of 2x in bytes written per byte stored; the crash ring keeps a killed daemon from losing them.
    double recorder_commit_interval_s = 30.0;
    // [recorder] journal: "wal" (readers and the recorder never wait for each other) or
    // "rollback" (fewer bytes written at commit intervals of 30 s and more; a commit waits for
    // running reads). docs/recorder.md, "Journal".
    std::string recorder_journal = "wal";
    // [recorder] crash_ring_dir: shared memory holding the samples not yet committed, so a killed
    // daemon loses none (store/crash_ring.hpp); "" runs without.
    std::string recorder_crash_ring_dir = "/dev/shm";
    // [recorder] lock_timeout_s: how long one write waits for a lock another program holds on the
    // database before the writer counts it locked, raises database_locked and tries again each
    // second (everything waits in order meanwhile; nothing is lost).
    double recorder_lock_timeout_s = 5.0;
    SafetyLimits safety;
    SteadyStateRule steady_state;
    std::map<std::string, InstrumentSpec> instruments;  // keyed by channel (air_temp_c, ...)
    DeviceConfig devices;
    SimulationConfig simulation;
    StandbyConfig standby;
    ApiConfig api;
    HttpConfig http;
    ArchiveConfig archive;
    NotificationsConfig notifications;
    PhysiologicalConfig physiological;
    std::filesystem::path source_dir;      // relative paths in the file resolve from here
    std::vector<std::string> warnings;     // unknown keys and similar, with file:line
    // Where each key present in the text was: "devices.chamber.register_map" -> "file:line:column";
    // array elements as "simulation.faults[0]". Validation names file, line and key from here.
    std::map<std::string, std::string> key_where;
    std::string source_name;               // the file in messages (empty: nothing parsed yet)
    unsigned file_mode = 0;                // permission bits of the file load_config read (0: not from a file)
    std::string source_sha256;             // SHA-256 of the TOML text parsed last: exports' provenance
    std::string source_text;               // that text (recorded with each trial's set-up)
};

// The text of config/manikind.toml, embedded at build time (CMake writes it into the build tree).
const char* default_config_toml();

// The configuration compiled into the program: the simulated lab (config/manikind.toml).
Config default_config();

// Parses TOML text over the defaults (keys absent from the text keep the default's value);
// `source_name` is used in messages. Throws manikind::UserError.
Config parse_config(const std::string& toml_text, const std::string& source_name);
Config parse_config(const std::string& toml_text, const std::string& source_name, const Config& base);

// Reads and parses a file. Throws manikind::UserError (missing file, syntax, types, ranges;
// a directory, device or a file over 1 MiB is refused before it is read).
Config load_config(const std::filesystem::path& path);

// Everything the daemon would refuse at start, beyond what parsing already refused: register
// maps that do not load, world effects and faults that do not parse, a control socket path too
// long for sockaddr_un, missing keys in mode = "real", a weak API token, a token in a file others
// can read. One message per problem, each naming file:line:column and the key; empty: fine.
// `manikin config check` and manikind both call this, so the two never disagree.
std::vector<std::string> validate(const Config& c);
// The part of validate() about [safety] and [standby] against the configured devices (also run
// by `manikin campaign check`): appends one line per problem.
void check_limits_fit_devices(const Config& c, std::vector<std::string>& problems);

// Throws manikind::UserError with every problem validate() finds, one per line.
void require_valid(const Config& c);

// Why a control API token is too weak (placeholder, short, low entropy), with how to make a good
// one; empty when it is fine.
std::string token_problem(const std::string& token);

}  // namespace manikind::config
