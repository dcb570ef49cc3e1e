// manikind: the data-acquisition and control daemon a lab leaves running.
//   manikind --config config/real-lab.toml          the lab's devices, real time
//   manikind                                        the simulated lab (built-in config), real time
//   manikind --virtual --campaign builtin:table-s3  the simulated lab on the virtual clock
// It serves the control API on a Unix socket until SIGINT/SIGTERM or a `shutdown` request.
// Under systemd (Type=notify) it says READY=1 once the socket listens, and feeds the watchdog
// only while both its acquisition tick and its control server are alive, so a hung daemon is
// restarted.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <csignal>
#include <cstdio>
#include <optional>
#include <string>
#include <sys/signalfd.h>
#include <sys/stat.h>
#include <unistd.h>

#include <systemd/sd-daemon.h>

#include <poll.h>

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "archive/background.hpp"
#include "daemon/config.hpp"
#include "daemon/control_api.hpp"
#include "daemon/lab_daemon.hpp"
#include "daemon/notifier.hpp"
#include "daemon/logging.hpp"
#include "base/user_error.hpp"
#include "analysis/physio.hpp"
#include "daemon/web_server.hpp"
#include "store/database.hpp"

namespace {

// What `manikin results` prints, so a batch run ends with its answer and not only "stopping".
void print_results_summary(manikind::LabDaemon& daemon, const std::string& campaign) {
    try {
        const auto r = daemon.results_json(campaign);
        std::printf("results of campaign %s (whole body, 95 %% CI over replicates)\n  case  n   Q_WB W/m²   95 %% CI\n",
                    campaign.c_str());
        const nlohmann::json none = nlohmann::json::object();
        for (const auto& c : r.contains("cases") ? r["cases"] : nlohmann::json::array()) {
            const auto& wb = c.contains("whole_body") ? c["whole_body"] : none;
            std::printf("  %4d  %d  %9.2f   [%.2f, %.2f]\n", c.value("case", 0), c.value("n_replicates", 0), wb.value("q_w_m2", 0.0),
                        wb.value("ci_low_w_m2", 0.0), wb.value("ci_high_w_m2", 0.0));
        }
        if (r.contains("physiological")) std::printf("%s", manikind::analysis::physio::summary_text(r["physiological"]).c_str());
        // A clothing campaign ends with its answer in clo and Ret (issue 64), not only W/m² per case.
        if (const auto cl = r.find("clothing"); cl != r.end() && cl->is_object()) {
            // The standards the campaign chose ([standards]), else the methods, said as such.
            std::string standards;
            if (const auto st = cl->find("standards"); st != cl->end() && st->is_object())
                for (const auto& [test, standard] : st->items())
                    if (standard.is_string()) standards += (standards.empty() ? "" : "; ") + test + ": " + standard.get<std::string>();
            if (standards.empty()) standards = "the methods of ASTM F1291 / ISO 15831 / ASTM F2370; the campaign names no standard";
            std::printf("clothing (%s; full table: manikin clothing --db ... --campaign %s)\n"
                        "  ensemble        It total, clo    Icl, clo         Ret total, m²Pa/W\n", standards.c_str(), campaign.c_str());
            auto cell = [](const nlohmann::json& v, const char* value, const char* u95, double scale) {
                if (!v.is_object() || !v[value].is_number()) return std::string("-");
                return fmt::format("{:.2f} ± {:.2f}", v[value].get<double>() * scale, v[u95].get<double>() * scale);
            };
            for (const auto& e : (*cl)["ensembles"]) {
                const auto& ins = e["insulation"];
                const auto& evap = e["evaporative"];
                std::printf("  %-14s  %-15s  %-15s  %s\n", e.value("id", "?").c_str(), cell(ins["total_parallel"], "clo", "U95_clo", 1.0).c_str(),
                            cell(ins["intrinsic_parallel"], "clo", "U95_clo", 1.0).c_str(),
                            cell(evap["total_parallel"], "value_m2pa_w", "U95_m2pa_w", 1.0).c_str());
            }
            if ((*cl)["left_out"].is_array() && !(*cl)["left_out"].empty())
                std::printf("  %zu trial(s) left out by the standards' stop rule (manikin clothing says which)\n", (*cl)["left_out"].size());
        }
        if (const auto ex = r.find("excluded_trials"); ex != r.end() && ex->is_array() && !ex->empty())
            std::printf("  %zu trial(s) excluded (see `manikin results --json`)\n", ex->size());
    } catch (const std::exception& e) {
        std::printf("no results for campaign %s: %s\n", campaign.c_str(), e.what());
    }
    std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
    using namespace manikind;
    CLI::App app{"manikind: sweating-manikin trials in a climate chamber (acquisition, control, recorder, API)"};
    std::string config_file, socket, campaign, database;
    bool virtual_clock = false, exit_when_done = false;
    double speed = 1.0;
    app.add_option("--config", config_file, "TOML configuration (default: the built-in simulated lab)");
    app.add_option("--socket", socket, "Control socket path (overrides [api] socket)");
    app.add_option("--database", database, "SQLite database (overrides [lab] database)");
    std::string http_listen;
    app.add_option("--http", http_listen, "Serve the operator console on HOST:PORT (loopback only; overrides [http] listen), "
                                          "e.g. 127.0.0.1:8470; port 0 picks a free one");
    app.add_flag("--virtual", virtual_clock, "Simulated lab only: run the virtual clock as fast as the CPU allows");
    app.add_option("--speed", speed, "Simulated lab in real time: this many times the wall clock (faster: --virtual)")
        ->check(CLI::Range(0.1, 10.0));
    app.add_option("--campaign", campaign, "Start this campaign at once (a campaign TOML file, or builtin:table-s3)");
    app.add_flag("--exit-when-done", exit_when_done, "Exit when the campaign given with --campaign has finished");
    std::optional<double> sim_air_speed_m_s;
    app.add_option("--sim-air-speed", sim_air_speed_m_s,
                   "Simulated lab: the enclosure's air speed in m/s (overrides [simulation] air_speed_m_s, 0.01: sealed; "
                   "0.4 for the clothing templates, ASTM F1291 / ISO 15831)")
        ->check(CLI::Range(0.0, 5.0));
    app.footer("Talk to it with `manikin status`, `manikin campaign run <file>`, `manikin trial watch`, `manikin results`.\n"
               "Mutating API commands need the token ([api] token, or the <socket>.token file it writes).");
    CLI11_PARSE(app, argc, argv);

    // Signals arrive on a descriptor, so shutdown is an ordinary event, not an async handler.
    sigset_t mask;
    sigemptyset(&mask);
    sigaddset(&mask, SIGINT);
    sigaddset(&mask, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &mask, nullptr);
    const int sig_fd = signalfd(-1, &mask, SFD_CLOEXEC | SFD_NONBLOCK);
    std::signal(SIGPIPE, SIG_IGN);
    // Files the daemon creates (database, captures, logs) are never world-readable.
    ::umask(::umask(0) | 0027);

    try {
        config::Config cfg = config_file.empty() ? config::default_config() : config::load_config(config_file);
        for (const auto& w : cfg.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
        if (!database.empty()) cfg.database = database;
        if (sim_air_speed_m_s) {
            if (cfg.mode != "simulated") throw UserError("--sim-air-speed needs mode = \"simulated\" (a real lab's fans set the air speed)");
            cfg.simulation.air_speed_m_s = *sim_air_speed_m_s;
        }
        if (!http_listen.empty()) {
            cfg.http.listen = http_listen;
            cfg.key_where["http.listen"] = "--http";
        }
        if (!socket.empty()) {
            cfg.api.socket = socket;
            cfg.key_where["api.socket"] = "--socket";  // problems with it are the option's, not the file's
        }
        config::require_valid(cfg);  // the same check as `manikin config check`
        set_log_level(cfg.log_level);
        if (virtual_clock && cfg.mode != "simulated") throw UserError("--virtual needs mode = \"simulated\"");
        ControlOptions api;
        api.socket_path = cfg.api.socket;
        api.tcp_port = static_cast<int>(cfg.api.tcp_port);
        api.max_clients = static_cast<std::size_t>(cfg.api.max_clients);
        api.idle_timeout_s = cfg.api.idle_timeout_s;
        api.partial_grace_s = cfg.api.partial_grace_s;
        api.max_clients_per_peer = static_cast<std::size_t>(cfg.api.max_clients_per_peer);
        // One daemon per socket, decided first: a refused second daemon touches no database and
        // no token file of the first.
        InstanceLock socket_lock = InstanceLock::acquire(api.socket_path, "control socket");
        api.token = load_or_create_token(cfg.api.token, api.socket_path);
        // What the run stored is counted from the file once the daemon, its recorder and every
        // connection of its own are gone (the block below): the file as the next reader finds it.
        struct RunTally {
            nlohmann::json recorder, storage;
            recorder::Database::RowMark mark;
            std::filesystem::path database;
        } tally;
        int exit_status = 0;
        {
            // [notifications]: made before the daemon so that it outlives every notice the daemon posts
            // (the last ones at its exit are tried once more as it stops).
            std::unique_ptr<Notifier> notifier;
            const auto& nc = cfg.notifications;
            if (!nc.webhook_url.empty() || (!nc.smtp_url.empty() && !nc.mail_to.empty())) {
                NotifierOptions no;
                no.lab_name = cfg.lab_name;
                no.events = std::set<std::string>(nc.events.begin(), nc.events.end());
                no.webhook_url = nc.webhook_url;
                no.webhook_format = nc.webhook_format;
                no.smtp_url = nc.smtp_url;
                no.mail_from = nc.mail_from;
                no.mail_to = nc.mail_to;
                no.min_interval_s = nc.min_interval_s;
                no.retries = static_cast<int>(nc.retries);
                no.timeout_s = nc.timeout_s;
                notifier = std::make_unique<Notifier>(no);
            }
            LabDaemon daemon({cfg, virtual_clock, speed});
            if (notifier) {
                daemon.set_notice_listener([n = notifier.get()](const std::string& kind, const std::string& severity, const std::string& title,
                                                                const std::string& body, std::int64_t utc_ns) {
                    n->post({kind, severity, title, body, utc_ns});
                });
                daemon.add_status_section("notifications", [n = notifier.get()] { return n->status_json(); });
            }
            // [archive]: forwarded from the recorder's file on a thread of its own (docs/archive.md).
            std::unique_ptr<archive::BackgroundForwarder> forwarder;
            if (!cfg.archive.postgresql.empty()) {
                archive::ForwardingOptions fo;
                fo.database = daemon.database_path();
                fo.conninfo = cfg.archive.postgresql;
                fo.lab_id = cfg.archive.lab_id;
                fo.lab_name = cfg.archive.lab_name.empty() ? cfg.lab_name : cfg.archive.lab_name;
                fo.interval = std::chrono::milliseconds(std::llround(cfg.archive.interval_s * 1000.0));
                forwarder = std::make_unique<archive::BackgroundForwarder>(
                    fo, [&daemon](const std::string& severity, const std::string& message) {
                        daemon.external_event(severity, "archive", message);
                    });
                daemon.add_status_section("archive", [f = forwarder.get()] { return f->status_json(); });
            }
            ControlServer server(daemon, api);
            server.adopt_socket_lock(std::move(socket_lock));
            server.start();
            std::unique_ptr<WebServer> console;
            if (!cfg.http.listen.empty()) {
                console = std::make_unique<WebServer>(daemon, api, parse_listen(cfg.http.listen, "http.listen"));
                console->start();
            }
            // A paced simulated lab says its pace: at --speed 10 a minute of the lab takes 6 s.
            const std::string clock_name = virtual_clock                           ? std::string("virtual clock")
                                           : cfg.mode == "simulated" && speed != 1.0 ? fmt::format("real clock x{:g}", speed)
                                                                                     : std::string("real clock");
            std::printf("manikind: %s lab, %s; database %s; control socket %s%s\n", cfg.mode.c_str(), clock_name.c_str(),
                        daemon.database_path().c_str(), api.socket_path.c_str(),
                        api.tcp_port ? fmt::format(" and 127.0.0.1:{}", api.tcp_port).c_str() : "");
            if (console) std::printf("manikind: console %s\n", console->url().c_str());
            std::fflush(stdout);
            ::sd_notifyf(0, "READY=1\nSTATUS=%s lab, control socket %s", cfg.mode.c_str(), api.socket_path.c_str());
            // The watchdog (WatchdogSec=) is fed at a third of its period, and only while the daemon
            // is really alive: its tick ran and the control server's timer ran within the last 5 s.
            std::uint64_t watchdog_usec = 0;
            const bool watchdog = ::sd_watchdog_enabled(0, &watchdog_usec) > 0 && watchdog_usec > 0;
            auto last_ping = std::chrono::steady_clock::now() - std::chrono::hours(1);
            auto feed_watchdog = [&] {
                if (!watchdog) return;
                const auto now = std::chrono::steady_clock::now();
                if (now - last_ping < std::chrono::microseconds(watchdog_usec / 3)) return;
                if (daemon.seconds_since_tick() > 5.0 || server.seconds_since_heartbeat() > 5.0) return;
                ::sd_notify(0, "WATCHDOG=1");
                last_ping = now;
            };
            std::string campaign_name;
            if (!campaign.empty()) {
                CampaignPlan plan = load_campaign_plan(campaign);
                if (const auto why = daemon.start_campaign(plan); !why.empty()) throw UserError(why);
                campaign_name = plan.name;
            }
            auto signalled = [&] {
                signalfd_siginfo si{};
                return ::read(sig_fd, &si, sizeof si) == static_cast<ssize_t>(sizeof si);
            };
            if (virtual_clock) {
                const double dt = cfg.simulation.step_s;
                std::string last_stage;
                // The signal descriptor is read at most every 20 ms of wall time, not at every step:
                // a read answering EAGAIN each virtual second was one of the daemon's ~36 system calls
                // per step (issue 36). A SIGTERM still stops it within 20 ms.
                constexpr auto kSignalCheck = std::chrono::milliseconds(20);
                auto next_signal_check = std::chrono::steady_clock::now();
                for (;;) {
                    if (const auto now = std::chrono::steady_clock::now(); now >= next_signal_check) {
                        if (signalled()) break;
                        next_signal_check = now + kSignalCheck;
                    }
                    if (server.shutdown_requested() || (console && console->shutdown_requested())) break;
                    feed_watchdog();
                    daemon.step_virtual(dt);
                    // Not status_json(): it measures the steady window and every device, each step.
                    const std::string stage = daemon.stage_line();
                    if (stage != last_stage) {
                        std::printf("t=%.0f s %s committed=%llu accepted=%llu\n", daemon.virtual_time_s(), stage.c_str(),
                                    static_cast<unsigned long long>(daemon.committed_rows()),
                                    static_cast<unsigned long long>(daemon.accepted_rows()));
                        std::fflush(stdout);
                        last_stage = stage;
                    }
                    if (exit_when_done && !daemon.campaign_active()) break;
                }
            } else {
                daemon.start_realtime();
                for (;;) {
                    pollfd p{sig_fd, POLLIN, 0};
                    ::poll(&p, 1, watchdog ? static_cast<int>(std::clamp<std::uint64_t>(watchdog_usec / 3000, 10, 500)) : 500);
                    feed_watchdog();
                    if (signalled() || server.shutdown_requested() || (console && console->shutdown_requested())) break;
                    if (exit_when_done && !campaign.empty() && !daemon.campaign_active()) break;
                }
            }
            // --exit-when-done: the exit status says how the campaign ended (0 done, 6 otherwise; docs/cli.md).
            if (exit_when_done && !campaign_name.empty() && !daemon.campaign_active()) {
                print_results_summary(daemon, campaign_name);
                const auto outcome = daemon.campaign_outcome_json(campaign_name);
                if (!outcome.value("ok", false)) {
                    exit_status = static_cast<int>(ExitStatus::not_done);
                    std::fprintf(stderr, "manikind: campaign '%s' ended %s (trials: %s%s): exit status %d\n", campaign_name.c_str(),
                                 outcome.value("state", "?").c_str(), outcome["trials"].dump().c_str(),
                                 outcome.value("model_fallbacks", 0) > 0 ? "; a physiological trial fell back to constant skin temperature" : "",
                                 exit_status);
                }
            }
            ::sd_notify(0, "STOPPING=1");
            std::printf("manikind: stopping\n");
            if (console) console->stop();
            server.stop();
            daemon.stop();
            {
                const auto st = daemon.status_json();
                tally.recorder = st["recorder"];
                tally.storage = st["storage"];
                tally.mark = daemon.row_mark();
                tally.database = daemon.database_path();
            }
            // What the last seconds committed goes now if the archive answers within 10 s; else at
            // the next start (nothing is lost either way).
            if (forwarder) {
                // Everything recorded goes to the archive before the exit, with progress; a second
                // SIGTERM/SIGINT (or 60 s without a chunk committed) ends the wait, and the next start
                // sends the rest: the local database keeps every row.
                std::printf("manikind: forwarding what is left to the archive (Ctrl-C again to leave it for the next start)\n");
                std::fflush(stdout);
                const bool complete = forwarder->finish(
                    std::chrono::seconds(60),
                    [](std::int64_t sent) {
                        std::printf("manikind: archive: %lld rows sent since the stop\n", static_cast<long long>(sent));
                        std::fflush(stdout);
                    },
                    [&] { return signalled(); });
                std::printf("manikind: archive: %s\n", complete ? "everything recorded is in the archive"
                                                              : "not everything is in the archive yet: the next start sends "
                                                                "the rest (nothing is lost)");
                std::fflush(stdout);
            }
        }
        // What this run recorded: a lab (and the soak test) checks nothing was lost. "stored" is
        // counted in the file, after the recorder closed, not taken from the recorder's tally:
        // readings lost after their commit (another program deleting the live -wal, issue 60)
        // show here, and the stop says so.
        const auto n = [](const nlohmann::json& v) { return static_cast<unsigned long long>(v.get<std::uint64_t>()); };
        const auto committed = n(tally.recorder["committed"]);
        unsigned long long in_file = 0;
        std::string count_error;
        try {
            in_file = static_cast<unsigned long long>(recorder::Database::open_read_only(tally.database).rows_since(tally.mark));
        } catch (const std::exception& e) {
            count_error = e.what();
        }
        std::printf("manikind: stopped: %llu readings accepted, %llu stored, %llu re-sent duplicates, %llu dropped, "
                    "%llu lost; %llu writes waiting\n",
                    n(tally.recorder["accepted"]), count_error.empty() ? in_file : committed, n(tally.recorder["duplicates"]),
                    n(tally.recorder["dropped_queue_full"]), n(tally.recorder["lost_after_retries"]),
                    n(tally.storage["deferred_writes"]));
        std::fflush(stdout);
        if (!count_error.empty()) {
            std::fprintf(stderr, "manikind: the readings stored could not be counted in %s (%s); the recorder's own count is "
                                 "given\n", tally.database.c_str(), count_error.c_str());
        } else if (in_file != committed) {
            std::fprintf(stderr, "manikind: %s holds %llu readings of this run, the recorder committed %llu: %lld lost after "
                                 "their commit (did a program other than SQLite open the database, or delete its -wal?)\n",
                         tally.database.c_str(), in_file, committed,
                         static_cast<long long>(committed) - static_cast<long long>(in_file));
            if (exit_status == 0) exit_status = static_cast<int>(ExitStatus::internal);
        }
        return exit_status;
    } catch (const UserError& e) {
        std::fprintf(stderr, "manikind: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "manikind: internal error: %s\n", e.what());
        return 1;
    }
}
