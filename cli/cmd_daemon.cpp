// The `manikin` commands that talk to a running daemon over its control socket, and the ones that
// read its database: status, live, campaign run|abort|pause|resume|check, setpoint, trial watch,
// results, campaigns, export.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"
#include "analysis/lab_report.hpp"
#include "analysis/physio.hpp"
#include "analysis/input_error.hpp"
#include "daemon/campaign_plan.hpp"
#include "daemon/config.hpp"
#include "base/toml_input.hpp"
#include "cli/campaign_source.hpp"
#include "cli/commands.hpp"
#include "daemon/control_client.hpp"
#include "store/database_export.hpp"
#include "store/export_target.hpp"
#include "store/hdf5_export.hpp"
#include "store/database.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"
#include "physics/sign_convention.hpp"

namespace manikind::cli {

namespace {

struct Conn {
    std::string socket = "manikind.sock";
    std::string token;
    double timeout_s = 10.0;
    bool json = false;
};

void add_conn_options(CLI::App* cmd, Conn& c, bool mutating) {
    cmd->add_option("--socket", c.socket, "The daemon's control socket ([api] socket; where ./manikind.sock is absent, the "
                                          "packaged service's /run/manikind/manikind.sock)")
        ->capture_default_str();
    if (mutating) cmd->add_option("--token", c.token, "API token (default: read from <socket>.token, or $MANIKIND_TOKEN)");
    cmd->add_option("--timeout", c.timeout_s, "Seconds to wait for the daemon's answer before saying what it waited for")
        ->capture_default_str()
        ->check(CLI::Range(0.1, 3600.0));
    cmd->add_flag("--json", c.json, "Print the daemon's JSON reply");
}

// The socket asked for; left at its default (./manikind.sock) where there is none, the packaged
// service's (docs/daemon.md, "The Debian package") when it is there: on a lab PC `manikin status`
// answers without --socket.
std::string socket_of(const Conn& c) {
    constexpr const char* packaged = "/run/manikind/manikind.sock";
    std::error_code ec;
    if (c.socket == "manikind.sock" && !std::filesystem::exists(c.socket, ec) && std::filesystem::exists(packaged, ec))
        return packaged;
    return c.socket;
}

nlohmann::json call(const Conn& c, nlohmann::json req, bool mutating) {
    const std::string socket = socket_of(c);
    if (mutating) {
        std::string token = c.token;
        if (token.empty())
            if (const char* env = std::getenv("MANIKIND_TOKEN")) token = env;
        if (token.empty()) token = read_token_file(socket);
        req["token"] = token;
    }
    auto reply = call_daemon(socket, req, c.timeout_s);
    if (!reply.value("ok", false))
        throw UserError::refused("the daemon refused: " + reply.value("error", std::string("?")));
    return reply;
}

std::string heat_flux_footer() { return std::string("Heat flux: ") + physics::heat_flux_sign + "."; }

std::string bar(double fraction, int width = 30) {
    const int filled = static_cast<int>(std::floor(std::clamp(fraction, 0.0, 1.0) * width));  // full only at 1
    return "[" + std::string(static_cast<std::size_t>(filled), '#') + std::string(static_cast<std::size_t>(width - filled), '.') + "]";
}

// "2026-11-03 14:05:09" (UTC) from nanoseconds since the epoch.
std::string utc_text(std::int64_t utc_ns) {
    const std::time_t t = static_cast<std::time_t>(utc_ns / 1'000'000'000);
    std::tm tm{};
    ::gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S", &tm);
    return buf;
}

// "12.34" or "—" for a JSON null (a channel not yet seen, a NaN).
std::string number_or_dash(const nlohmann::json& v, int decimals) {
    return v.is_number() ? fmt::format("{:.{}f}", v.get<double>(), decimals) : std::string("—");
}

std::string age_text(const nlohmann::json& age_s) {
    return age_s.is_number() ? fmt::format("{:.1f} s ago", age_s.get<double>()) : std::string("never");
}

// One measured value: "chamber air      35.21 °C  (setpoint 35.30 °C)  good, 0.4 s ago".
void print_measured(const nlohmann::json& measured) {
    const struct {
        const char* key;
        const char* label;
        int decimals;
    } rows[] = {{"chamber_air_temp_c", "chamber air temp", 2}, {"chamber_air_rh_pct", "chamber air RH", 1},
                {"air_speed_m_s", "air speed", 2},            {"mean_skin_temp_c", "mean skin temp", 2},
                {"mean_heat_flux_w_m2", "mean heat flux", 1}};
    for (const auto& row : rows) {
        if (!measured.contains(row.key)) continue;
        const auto& m = measured[row.key];
        const std::string unit = m.value("unit", "");
        std::string setpoint;
        if (m.contains("setpoint"))
            setpoint = m["setpoint"].is_number() ? fmt::format("  (setpoint {} {})", number_or_dash(m["setpoint"], row.decimals), unit)
                                                 : std::string("  (no setpoint sent)");
        std::printf("  %-17s %8s %-5s%s  %s, %s  [%s]\n", row.label, number_or_dash(m["value"], row.decimals).c_str(),
                    unit.c_str(), setpoint.c_str(), m["quality"].is_string() ? m["quality"].get<std::string>().c_str() : "no data",
                    age_text(m["age_s"]).c_str(), m.value("source", "").c_str());
    }
}

void print_status(const nlohmann::json& s) {
    std::printf("%s lab, %s clock, t = %.0f s; database %s\n", s["mode"].get<std::string>().c_str(),
                s["clock"].get<std::string>().c_str(), s["time_s"].get<double>(), s["database"].get<std::string>().c_str());
    if (s["campaign"].is_null()) std::printf("no campaign running\n");
    else
        std::printf("campaign %s: %d of %d trials done; stage %s%s\n", s["campaign"].get<std::string>().c_str(),
                    s["trials_done"].get<int>(), s["trials_total"].get<int>(), s["stage"].get<std::string>().c_str(),
                    s["paused"].get<bool>() ? " (paused)" : "");
    if (s.contains("awaiting_operator") && s["awaiting_operator"].is_string())
        std::printf("WAITING FOR THE OPERATOR: %s; when done: manikin continue\n", s["awaiting_operator"].get<std::string>().c_str());
    if (s.contains("trial")) {
        const auto& t = s["trial"];
        std::printf("trial %ld: case %d replicate %d, %.0f s in stage\n", t["id"].get<long>(), t["case"].get<int>(),
                    t["replicate"].get<int>(), t["stage_elapsed_s"].get<double>());
        if (t.contains("settling") && t["settling"].is_object()) {
            // Chamber settling: what is awaited, how far off each quantity is, when it may be done.
            const auto& st = t["settling"];
            const auto num = [](const nlohmann::json& v, const char* f) {
                return v.is_number() ? fmt::format(fmt::runtime(f), v.get<double>()) : std::string("-");
            };
            std::printf("  awaiting: %s\n", printable(st.value("criterion", ""), 300).c_str());
            std::printf("  air %s °C (%s °C off), RH %s %% (%s %% off); on target %s of %s min; ready %s\n",
                        num(st["air_c"], "{:.2f}").c_str(), num(st["air_off_c"], "{:+.2f}").c_str(),
                        num(st["rh_pct"], "{:.1f}").c_str(), num(st["rh_off_pct"], "{:+.1f}").c_str(),
                        num(st["on_target_s"].is_number() ? nlohmann::json(st["on_target_s"].get<double>() / 60) : st["on_target_s"], "{:.1f}").c_str(),
                        num(st["window_s"].is_number() ? nlohmann::json(st["window_s"].get<double>() / 60) : st["window_s"], "{:.0f}").c_str(),
                        st.value("timed_out", false) ? "never: timed out, holding (see alarms)"
                        : st["eta_s"].is_number()
                            ? fmt::format("in about {:.0f} min ({})", st["eta_s"].get<double>() / 60,
                                          st.contains("eta_high_s") && st["eta_high_s"].is_number()
                                              ? fmt::format("{:.0f}-{:.0f} min", st["eta_low_s"].get<double>() / 60,
                                                            st["eta_high_s"].get<double>() / 60)
                                              : std::string("or later: the pace is uncertain"))
                                  .c_str()
                            : "unknown (not yet closing in)");
            if (st.contains("failing") && st["failing"].is_array() && !st["failing"].empty()) {
                std::string what;
                for (const auto& f : st["failing"]) what += (what.empty() ? "" : "; ") + f.get<std::string>();
                std::printf("  not yet: %s\n", printable(what, 400).c_str());
            }
        }
        if (t.contains("model") && t["model"].is_object()) {
            // A physiological trial: the model's phase, how long it has run (and when
            // preconditioning gives up), the model's clock, core and mean skin.
            const auto& m = t["model"];
            const std::string phase = m.value("phase", "?");
            std::string in_phase;
            if (m.contains("phase_elapsed_s") && m["phase_elapsed_s"].is_number()) {
                in_phase = fmt::format(", {:.1f} min in it", m["phase_elapsed_s"].get<double>() / 60);
                if (m.contains("phase_limit_s"))
                    in_phase += fmt::format(" (falls back at {:.0f} min; every zone at the model's start for {:.0f} of {:.0f} s)",
                                            m["phase_limit_s"].get<double>() / 60, m.value("on_start_s", 0.0), m.value("hold_s", 0.0));
            }
            const double duration_s = m.value("duration_s", 0.0), model_s = m.value("model_time_s", 0.0);
            std::printf("  model %s: %s%s; model time %.1f of %.0f min %s; core %.2f °C, mean skin %.2f °C%s\n",
                        printable(m.value("model", ""), 60).c_str(), phase.c_str(), in_phase.c_str(), model_s / 60, duration_s / 60,
                        bar(duration_s > 0 ? std::min(1.0, model_s / duration_s) : 0.0).c_str(), m.value("core_temp_c", 0.0),
                        m.value("mean_skin_temp_c", 0.0),
                        m.contains("fallback_reason") ? (" FELL BACK: " + printable(m["fallback_reason"].get<std::string>(), 200)).c_str() : "");
        }
        if (t.contains("steady_progress")) {
            const double progress = t["steady_progress"].get<double>();
            // Floor, not round: 99.9 % must not print as 100 % while the rule says no.
            std::printf("  steady %s %3.0f %%%s\n", bar(progress).c_str(), std::floor(100.0 * progress),
                        t["steady"].get<bool>() ? "  STEADY" : "  not steady");
            const auto& wz = t["worst_zone"];
            std::printf("    window filled %3.0f %% of %.0f min; worst zone %s range %s °C (limit < %.3f °C); "
                        "%.0f of %.0f min\n",
                        std::floor(100.0 * t["window_filled_fraction"].get<double>()), t["window_s"].get<double>() / 60.0,
                        wz.is_object() ? fmt::format("{} ({})", wz["zone"].get<int>(), wz["name"].get<std::string>()).c_str() : "—",
                        number_or_dash(t["worst_zone_range_c"], 3).c_str(), t["limit_c"].get<double>(),
                        std::floor(t["elapsed_s"].get<double>() / 60.0), t["min_duration_s"].get<double>() / 60.0);
            if (t.contains("heat_loss") && t["heat_loss"].is_object()) {
                const auto& h = t["heat_loss"];
                if (h.value("observed", false) && h["drift_fraction"].is_number())
                    std::printf("    heat loss (the clothing standards' rule): moves %.1f %% over the window (limit %.1f %%), "
                                "mean skin %.3f °C: %s\n",
                                100.0 * h["drift_fraction"].get<double>(), 100.0 * h.value("limit_fraction", 0.03),
                                h["mean_skin_drift_c"].is_number() ? h["mean_skin_drift_c"].get<double>() : 0.0,
                                h.value("steady", false) ? "steady" : "not yet");
                else
                    std::printf("    heat loss (the clothing standards' rule): not yet sampled over a whole window\n");
            }
        }
    }
    if (s.contains("measured")) {
        std::printf("measured:  (heat flux %s)\n", physics::heat_flux_sign);
        print_measured(s["measured"]);
    }
    std::printf("%-11s %-5s %-5s %9s %6s %6s %6s %6s %6s  %s\n", "device", "conn", "stale", "samples", "cksum", "tmout", "exc",
                "recon", "faults", "last error");
    for (const auto& d : s["devices"])
        std::printf("%-11s %-5s %-5s %9llu %6llu %6llu %6llu %6llu %6llu  %s\n", d["name"].get<std::string>().c_str(),
                    d["connected"].get<bool>() ? "yes" : "NO", d["stale"].get<bool>() ? "YES" : "no",
                    d["samples"].get<unsigned long long>(), d["checksum_errors"].get<unsigned long long>(),
                    d["timeouts"].get<unsigned long long>(), d["exceptions"].get<unsigned long long>(),
                    d["reconnects"].get<unsigned long long>(), d["device_faults"].get<unsigned long long>(),
                    d["last_error"].get<std::string>().c_str());
    const auto& r = s["recorder"];
    std::printf("recorder: %llu samples committed, %llu not stored (%llu queue full, %llu re-sent duplicates, %llu lost)\n",
                r["committed"].get<unsigned long long>(), r["dropped"].get<unsigned long long>(),
                r.value("dropped_queue_full", 0ULL), r.value("duplicates", 0ULL), r.value("lost_after_retries", 0ULL));
    // Where uncommitted samples wait (docs/recorder.md, "Durability"), and what a crash left there.
    const std::string ring = r.value("crash_ring", std::string());
    std::printf("          %llu waiting for their commit, %s; %llu recovered at start from a crashed daemon\n",
                r.value("queue_rows", 0ULL), ring.empty() ? "NOT kept safe from a crash (no crash ring)" : ("kept in " + ring).c_str(),
                r.value("recovered_from_crash_ring", 0ULL));
    if (r.value("locked", false))
        std::printf("          COMMITS WAITING: another program holds the database's lock (%llu attempts so far)\n",
                    r.value("locked_commits", 0ULL));
    if (const std::string journal = r.value("journal", std::string()); !journal.empty())
        std::printf("          journal: %s\n", journal == "wal" ? "WAL (readers never wait)"
                                                                 : "rollback (a commit waits for running reads)");
}

}  // namespace

void add_daemon_commands(CLI::App& app) {
    if (building("status")) {
        auto c = std::make_shared<Conn>();
        auto* cmd = app.add_subcommand("status", "The running daemon: campaign, trial stage, devices and their counters");
        add_conn_options(cmd, *c, false);
        cmd->footer(heat_flux_footer());
        cmd->callback([c] {
            const auto r = call(*c, {{"cmd", "status"}}, false);
            if (c->json) std::printf("%s\n", r["status"].dump(2).c_str());
            else print_status(r["status"]);
        });
    }
    if (building("campaign")) {
        auto* campaign = app.add_subcommand("campaign", "Start, abort, pause or resume a campaign on the running daemon");
        campaign->require_subcommand(1);
        auto c = std::make_shared<Conn>();
        auto file = std::make_shared<std::string>();
        auto* run = campaign->add_subcommand("run", "Queue a campaign: a TOML file (cases x replicates), or builtin:table-s3");
        run->add_option("file", *file, "Campaign file (see config/campaign-example.toml) or builtin:table-s3")->required();
        auto wait = std::make_shared<bool>(false);
        run->add_flag("--wait", *wait, "Wait for the campaign to end; exit 0 when every trial is done, 6 when it ended "
                                       "aborted, failed or interrupted");
        add_conn_options(run, *c, true);
        run->footer("With --wait: exit status 0 when the campaign ended done with every planned trial done, 6 when it ended "
                    "otherwise (docs/cli.md); the daemon must stay reachable meanwhile (status 3 if it goes away).");
        run->callback([c, file, wait] {
            nlohmann::json req{{"cmd", "start_campaign"}};
            if (*file == "builtin:table-s3") {
                req["builtin"] = "table-s3";
                req["name"] = "table-s3";
            } else {
                std::ifstream in(*file);
                if (!in) throw UserError(fmt::format("{}: cannot open the campaign file", *file));
                std::stringstream ss;
                ss << in.rdbuf();
                req["plan_toml"] = ss.str();
                req["source"] = *file;
            }
            call(*c, req, true);
            if (!*wait) {
                if (c->json) std::printf("{\"ok\":true}\n");
                else std::printf("campaign queued; follow it with `manikin trial watch`\n");
                return;
            }
            // The name the daemon knows it by: the plan's, parsed here as the daemon parsed it.
            const std::string name = req.contains("name") ? req["name"].get<std::string>()
                                                          : parse_campaign_plan(req["plan_toml"].get<std::string>(), *file).name;
            if (!c->json) std::printf("campaign '%s' queued; waiting for it to end\n", name.c_str());
            std::fflush(stdout);
            nlohmann::json outcome;
            for (;;) {
                outcome = call(*c, {{"cmd", "campaign_outcome"}, {"campaign", name}}, false)["outcome"];
                if (!outcome.value("active", false)) break;
                std::this_thread::sleep_for(std::chrono::seconds(2));  // a person's pace: trials last an hour
            }
            const bool ok = outcome.value("ok", false);
            if (c->json) std::printf("%s\n", nlohmann::json{{"ok", ok}, {"outcome", outcome}}.dump().c_str());
            if (!ok)
                throw UserError::campaign_not_done(
                    fmt::format("campaign '{}' ended {} (trials: {}){}", name, outcome.value("state", "?"),
                                outcome.contains("trials") ? outcome["trials"].dump() : "{}",
                                outcome.value("model_fallbacks", 0) > 0
                                    ? fmt::format("; {} physiological trial(s) fell back to constant skin temperature",
                                                  outcome.value("model_fallbacks", 0))
                                    : std::string()),
                    outcome);
            if (!c->json) std::printf("campaign '%s' done: every trial done\n", name.c_str());
        });
        {
            auto check_file = std::make_shared<std::string>(), config_file = std::make_shared<std::string>();
            auto json = std::make_shared<bool>(false);
            auto* check = campaign->add_subcommand(
                "check", "Parse a campaign file as the daemon would: unknown keys are errors (file:line:column, "
                         "with the nearest known key), setpoints checked against [safety]");
            check->add_option("file", *check_file, "Campaign file")->required();
            check->add_option("--config", *config_file, "Daemon config whose [safety] limits apply (default: built-in limits)");
            check->add_flag("--json", *json, "Print the parsed plan as JSON");
            check->footer("Exit status 0 when the plan is valid, 5 when it has errors, 2 when a file cannot be read (docs/cli.md).");
            check->callback([check_file, config_file, json] {
                const auto text = toml_input::read_file(*check_file);
                if (!text) throw UserError(fmt::format("{}: cannot open the campaign file", *check_file));
                const auto cfg = config_file->empty() ? config::default_config() : config::load_config(*config_file);
                // The files were read: what is wrong in the plan is the check's negative verdict.
                const CampaignPlan plan = [&] {
                    try {
                        return parse_campaign_plan(*text, *check_file);
                    } catch (const UserError& e) {
                        throw UserError::check_failed(e.what());
                    }
                }();
                if (const auto why = check_plan_against_limits(plan, cfg.safety); !why.empty())
                    throw UserError::check_failed(fmt::format("{}: {}", *check_file, why));
                // The limits themselves must fit the manikin, or every case trips whatever it asks.
                std::vector<std::string> limit_problems;
                config::check_limits_fit_devices(cfg, limit_problems);
                if (!limit_problems.empty()) throw UserError::check_failed(limit_problems.front());
                if (const auto why = check_plan_against_devices(plan, cfg); !why.empty())
                    throw UserError::check_failed(fmt::format("{}: {}", *check_file, why));
                if (*json) {
                    nlohmann::json cases = nlohmann::json::array();
                    for (const auto& pc : plan.cases) {
                        nlohmann::json one = {{"id", pc.id}, {"chamber_temp_c", pc.chamber_temp_c}, {"chamber_rh_pct", pc.chamber_rh_pct},
                                              {"skin_setpoint_c", pc.skin_setpoint_c}, {"wet", pc.wet},
                                              {"sweat_rate_g_m2_h", pc.sweat_rate_g_m2_h}};
                        if (!pc.ensemble.empty()) one["ensemble"] = pc.ensemble;
                        if (!pc.test.empty()) one["test"] = pc.test;
                        if (pc.model) one["model"] = case_conditions_json(pc).at("model");
                        cases.push_back(one);
                    }
                    std::printf("%s\n", nlohmann::json{{"ok", true}, {"name", plan.name}, {"replicates", plan.replicates},
                                                        {"trial_duration_s", plan.trial_duration_s},
                                                        {"settle_window_s", plan.settle_window_s},
                                                        {"settle_timeout_s", plan.settle_timeout_s}, {"cases", cases}}
                                                .dump(2)
                                                .c_str());
                } else {
                    // Settling dominates a lab day: each trial waits for the enclosure first. A
                    // physiological case lasts its model's duration (plus the zones' preconditioning).
                    const std::size_t trials = plan.cases.size() * static_cast<std::size_t>(plan.replicates);
                    double minutes = 0.0;
                    std::size_t physiological = 0;
                    for (const auto& pc : plan.cases) {
                        minutes += (pc.model ? pc.model->duration_s : plan.trial_duration_s) / 60.0;
                        physiological += pc.model ? 1 : 0;
                    }
                    const auto n_cases = static_cast<double>(plan.cases.size());
                    const std::string length =
                        physiological == 0 ? fmt::format("trials of {:.0f} min", plan.trial_duration_s / 60.0)
                        : physiological == plan.cases.size()
                            ? fmt::format("physiological trials of {:.0f} min of model time each on average", minutes / n_cases)
                            : fmt::format("trials ({} case(s) physiological) of {:.0f} min on average", physiological,
                                          minutes / n_cases);
                    std::printf("%s: ok: campaign '%s', %zu case(s) x %d replicate(s) = %zu %s, each after "
                                "chamber settling (at least %.0f min, at most %.0f min): %.1f h or more in all\n",
                                check_file->c_str(), plan.name.c_str(), plan.cases.size(), plan.replicates, trials, length.c_str(),
                                plan.settle_window_s / 60.0, plan.settle_timeout_s / 60.0,
                                static_cast<double>(plan.replicates) * (minutes + n_cases * plan.settle_window_s / 60.0) / 60.0);
                }
            });
        }
        for (const char* name : {"abort", "pause", "resume"}) {
            auto* sub = campaign->add_subcommand(name, fmt::format("{} the running campaign", name));
            add_conn_options(sub, *c, true);
            auto reason = std::make_shared<std::string>();
            if (std::string(name) == "abort") {
                sub->add_option("--reason", *reason, "Why (recorded in the event log with your user name)");
                sub->footer("Stops heating, ends the running trial and the campaign (and the queue), and puts the chamber "
                            "and manikin in [standby].");
            }
            sub->callback([c, name, reason] {
                nlohmann::json req{{"cmd", name}};
                if (!reason->empty()) req["reason"] = *reason;
                call(*c, req, true);
                std::printf("%s\n", c->json ? "{\"ok\":true}" : "done");
            });
        }
    }
    if (building("continue")) {
        auto c = std::make_shared<Conn>();
        auto* cmd = app.add_subcommand("continue", "Tell the daemon the operator did what it waits for (dressed the manikin for "
                                                   "a clothing test); recorded with who said it");
        add_conn_options(cmd, *c, true);
        cmd->footer("`manikin status` says what the daemon waits for (\"WAITING FOR THE OPERATOR\"); so does the console,\n"
                    "whose Continue button does the same. A simulated lab's operator answers at once unless\n"
                    "[simulation] operator_prompts = \"wait\" (docs/daemon.md, \"Operator prompts\").");
        cmd->callback([c] {
            const auto before = call(*c, {{"cmd", "status"}}, false)["status"];
            call(*c, {{"cmd", "continue"}}, true);
            if (c->json) std::printf("{\"ok\":true}\n");
            else std::printf("continued: %s\n", before.value("awaiting_operator", nlohmann::json("")).is_string()
                                                    ? before["awaiting_operator"].get<std::string>().c_str()
                                                    : "");
        });
    }
    if (building("setpoint")) {
        auto c = std::make_shared<Conn>();
        auto temp = std::make_shared<double>(), rh = std::make_shared<double>();
        auto* cmd = app.add_subcommand("setpoint", "Set the chamber's temperature and humidity (checked against [safety])");
        cmd->add_option("--chamber-temp", *temp, "°C")->required();
        cmd->add_option("--chamber-rh", *rh, "%")->required();
        add_conn_options(cmd, *c, true);
        cmd->footer("A setpoint outside the daemon's [safety] limits is refused: exit status 4 (docs/cli.md).");
        cmd->callback([c, temp, rh] {
            call(*c, {{"cmd", "set_chamber"}, {"chamber_temp_c", *temp}, {"chamber_rh_pct", *rh}}, true);
            if (c->json)
                std::printf("%s\n", nlohmann::json{{"ok", true}, {"chamber_temp_c", *temp}, {"chamber_rh_pct", *rh}}.dump().c_str());
            else
                std::printf("chamber setpoints sent\n");
        });
    }
    if (building("note")) {
        struct NoteArgs {
            std::string campaign, kind = "comment", text, author, trial;
        };
        auto c = std::make_shared<Conn>();
        auto a = std::make_shared<NoteArgs>();
        auto* cmd = app.add_subcommand("note", "Write in the lab notebook: a note on a campaign or one of its trials, "
                                               "stored by the daemon with the time and its author (append-only)");
        cmd->add_option("text", a->text, "The note (quote it; newlines allowed, at most 4000 bytes)")->required();
        cmd->add_option("--campaign", a->campaign, "The campaign the note is about")->required();
        cmd->add_option("--trial", a->trial,
                        "A trial of it, by the name every export and report gives it (c03-r2: case 3, replicate 2) or its "
                        "database id (the running trial's: `manikin status --json`, trial.id)");
        cmd->add_option("--kind", a->kind, "comment, operator (who ran it), ensemble (what the manikin wore), garment")
            ->capture_default_str()
            ->check(CLI::IsMember({"comment", "operator", "ensemble", "garment"}));
        cmd->add_option("--author", a->author, "Who writes it (default: the user running this command)");
        add_conn_options(cmd, *c, true);
        cmd->footer("Notes travel with the campaign: `manikin notes`, every export (campaign.json \"notes\", HDF5 /notes),\n"
                    "the archive and the reports. A note is never edited: write a correcting note instead.\n"
                    "Example: manikin note --campaign astm-0425 --kind ensemble \"coverall #3, washed twice\"");
        cmd->callback([c, a] {
            std::string author = a->author;
            if (author.empty())
                if (const char* user = std::getenv("USER")) author = user;
            nlohmann::json req{{"cmd", "note"}, {"campaign", a->campaign}, {"kind", a->kind}, {"text", a->text}};
            if (!author.empty()) req["author"] = author;
            if (!a->trial.empty()) {
                // Digits: a database id; anything else the daemon looks up as a trial's name (c03-r2).
                const bool id = a->trial.size() <= 15 && std::all_of(a->trial.begin(), a->trial.end(), [](char ch) { return ch >= '0' && ch <= '9'; });
                if (id) req["trial"] = std::stoll(a->trial);
                else req["trial"] = a->trial;
            }
            call(*c, req, true);
            if (c->json) std::printf("%s\n", nlohmann::json{{"ok", true}}.dump().c_str());
            else std::printf("note stored on '%s'%s\n", a->campaign.c_str(), a->trial.empty() ? "" : fmt::format(" trial {}", a->trial).c_str());
        });
    }
    if (building("notes")) {
        auto c = std::make_shared<Conn>();
        auto campaign = std::make_shared<std::string>();
        auto db = std::make_shared<std::string>();
        auto* cmd = app.add_subcommand("notes", "The lab notebook of a campaign: time, author, kind, trial, text; from the running "
                                                "daemon, or with --db from its database (no daemon needed)");
        cmd->add_option("--campaign", *campaign, "The campaign")->required();
        cmd->add_option("--db", *db, "Read the notes from this database (read-only) instead of asking the daemon");
        add_conn_options(cmd, *c, false);
        cmd->callback([c, campaign, db] {
            nlohmann::json notes;
            if (!db->empty()) {
                auto database = recorder::Database::open_read_only(*db);
                const auto id = database.find_campaign(*campaign);
                if (!id) throw UserError(fmt::format("{}: no campaign named '{}'", *db, printable(*campaign, 100)));
                const auto trial_name = exported_trial_ids(database, *id);
                notes = nlohmann::json::array();
                for (const auto& n : database.notes(*id)) {
                    nlohmann::json e{{"id", n.id}, {"utc", analysis::iso_utc_ms(n.utc_ns)}, {"author", n.author}, {"kind", n.kind}, {"text", n.text}};
                    e["trial_id"] = n.trial_id ? nlohmann::json(*n.trial_id) : nlohmann::json(nullptr);
                    if (const auto it = n.trial_id ? trial_name.find(*n.trial_id) : trial_name.end(); it != trial_name.end())
                        e["trial"] = it->second;
                    notes.push_back(std::move(e));
                }
            } else {
                notes = call(*c, {{"cmd", "notes"}, {"campaign", *campaign}}, false)["notes"];
            }
            if (c->json) {
                std::printf("%s\n", dump_json(notes, 2).c_str());
                return;
            }
            if (notes.empty()) std::printf("no notes on '%s' yet (manikin note --campaign %s \"...\")\n", campaign->c_str(), campaign->c_str());
            for (const auto& n : notes) {
                const std::string trial = n["trial_id"].is_null() ? std::string("campaign")
                                          : n.contains("trial") ? n["trial"].get<std::string>()
                                                                : fmt::format("trial {}", n["trial_id"].get<long long>());
                std::printf("%s  %-10s %-8s %-10s %s\n", n.value("utc", "").c_str(), printable(n.value("author", ""), 40).c_str(),
                            n.value("kind", "").c_str(), trial.c_str(), n.value("text", "").c_str());
            }
        });
    }
    if (building("ack") || building("shelve")) {
        // Acknowledge or shelve an alarm from the terminal (issue 64: the console's token pasted into
        // a page was the only way): the daemon records who, the Unix user over the socket.
        struct AlarmArgs {
            std::int64_t id = 0;
            double hours = 1.0;
        };
        for (const char* name : {"ack", "shelve"}) {
            if (!building(name)) continue;
            auto c = std::make_shared<Conn>();
            auto a = std::make_shared<AlarmArgs>();
            const bool shelve = std::string(name) == "shelve";
            auto* cmd = app.add_subcommand(name, shelve ? "Shelve an open alarm for a while (at most 8 h; it comes back by itself), recorded with who"
                                                        : "Acknowledge an open alarm (someone is on it; it does not clear the cause), recorded with who");
            cmd->add_option("id", a->id, "The alarm's id (`manikin alarms`, first column)")->required()->check(CLI::Range(std::int64_t{1}, std::int64_t{9'000'000'000'000'000}));
            if (shelve) cmd->add_option("--hours", a->hours, "How long")->capture_default_str()->check(CLI::Range(0.01, 8.0));
            add_conn_options(cmd, *c, true);
            cmd->callback([c, a, shelve] {
                nlohmann::json req{{"cmd", shelve ? "shelve_alarm" : "ack_alarm"}, {"id", a->id}};
                if (shelve) req["duration_s"] = a->hours * 3600.0;
                call(*c, req, true);
                if (c->json) std::printf("{\"ok\":true}\n");
                else std::printf("alarm %lld %s\n", static_cast<long long>(a->id),
                                 shelve ? fmt::format("shelved for {:g} h", a->hours).c_str() : "acknowledged");
            });
        }
    }
    if (building("alarms")) {
        auto c = std::make_shared<Conn>();
        auto history = std::make_shared<bool>(false);
        auto* cmd = app.add_subcommand("alarms", "The daemon's open alarms (active, returned but unacknowledged, shelved), or the closed ones");
        cmd->add_flag("--history", *history, "The closed alarms instead (returned and acknowledged)");
        add_conn_options(cmd, *c, false);
        cmd->footer("States (ISA-18.2): UNACK, ACKED, RTN_UNACK (returned, not acknowledged), SHELVED, NORMAL (closed).\n"
                    "Acknowledge with `manikin ack ID`, shelve with `manikin shelve ID --hours H` (who is recorded: your Unix user),\n"
                    "in the console, or {\"cmd\":\"ack_alarm\",\"id\":N} on the socket (docs/daemon.md).");
        cmd->callback([c, history] {
            const auto reply = call(*c, {{"cmd", *history ? "alarm_history" : "alarms"}}, false);
            if (c->json) {
                std::printf("%s\n", dump_json(reply["alarms"], 2).c_str());
                return;
            }
            if (reply["alarms"].empty()) std::printf("%s\n", *history ? "no closed alarms" : "no open alarms");
            for (const auto& al : reply["alarms"])
                std::printf("%6lld  %-9s %-5s %-16s %s%s\n", al.value("id", 0LL), al.value("state", "").c_str(),
                            al.value("severity", "").c_str(), al.value("kind", "").c_str(), al.value("message", "").c_str(),
                            al.value("count", 1) > 1 ? fmt::format(" (x{})", al.value("count", 1)).c_str() : "");
        });
    }
    if (building("trial")) {
        auto c = std::make_shared<Conn>();
        auto once = std::make_shared<bool>(false);
        auto* trial = app.add_subcommand("trial", "Follow the running trial");
        trial->require_subcommand(1);
        auto* watch = trial->add_subcommand("watch", "Live status with a progress bar toward steady state (Ctrl-C to stop)");
        add_conn_options(watch, *c, false);
        watch->add_flag("--once", *once, "Print one update and exit (implied by --json: one JSON document)");
        watch->footer(heat_flux_footer());
        watch->callback([c, once] {
            // Clear the screen only on a terminal; a pipe or a log file gets plain blocks.
            const bool terminal = ::isatty(STDOUT_FILENO) == 1;
            for (bool first = true;; first = false) {
                const auto r = call(*c, {{"cmd", "status"}}, false);
                if (c->json) std::printf("%s\n", r["status"].dump(2).c_str());
                else {
                    if (terminal) std::printf("\033[H\033[2J");
                    else if (!first) std::printf("\n");
                    print_status(r["status"]);
                }
                std::fflush(stdout);
                if (*once || c->json || r["status"]["campaign"].is_null()) break;
                std::this_thread::sleep_for(std::chrono::seconds(1));
            }
        });
    }
    if (building("results")) {
        auto c = std::make_shared<Conn>();
        auto campaign = std::make_shared<std::string>();
        auto* cmd = app.add_subcommand("results", "Whole-body heat flux per case with 95 % CIs, from the running daemon");
        cmd->add_option("--campaign", *campaign, "Campaign name (default: the last one run)");
        add_conn_options(cmd, *c, false);
        cmd->footer(heat_flux_footer() +
                    "\nNo results yet is not an error: exit status 0, and under --json {\"campaign\": ..., \"cases\": [],\n"
                    "\"note\": ...} (docs/cli.md).");
        cmd->callback([c, campaign] {
            nlohmann::json req{{"cmd", "results"}};
            if (!campaign->empty()) req["campaign"] = *campaign;
            const auto r = call(*c, req, false);
            if (r["results"].is_null()) {
                const std::string note = r.value("note", std::string("no results yet"));
                if (c->json)
                    std::printf("%s\n", nlohmann::json{{"campaign", r.value("campaign", nlohmann::json())},
                                                       {"cases", nlohmann::json::array()}, {"note", note}}
                                            .dump(2)
                                            .c_str());
                else
                    std::printf("%s\n", note.c_str());
                return;
            }
            if (c->json) {
                auto j = r["results"];
                j["heat_flux_sign"] = physics::heat_flux_sign;
                std::printf("%s\n", j.dump(2).c_str());
                return;
            }
            std::printf("campaign %s%s; heat flux %s\n  case  n   Q_WB W/m²   U (95 %%)   95 %% CI\n",
                        r["campaign"].get<std::string>().c_str(),
                        r["results"].value("interim", false) ? " (interim: the trials done so far)" : "", physics::heat_flux_sign);
            for (const auto& cs : r["results"]["cases"]) {
                const auto& wb = cs["whole_body"];
                std::printf("  %4d  %d  %9.2f  %9.2f   [%.2f, %.2f]\n", cs.value("case", 0), cs.value("n_replicates", 0),
                            wb.value("q_w_m2", 0.0), wb.value("U", 0.0), wb.value("ci_low_w_m2", 0.0), wb.value("ci_high_w_m2", 0.0));
            }
            if (r["results"].contains("physiological"))
                std::printf("%s", analysis::physio::summary_text(r["results"]["physiological"]).c_str());
        });
    }
    if (building("live")) {
        auto c = std::make_shared<Conn>();
        auto* cmd = app.add_subcommand("live", "Every live channel of the running daemon: value, unit, quality and age");
        add_conn_options(cmd, *c, false);
        cmd->footer(heat_flux_footer());
        cmd->callback([c] {
            const auto r = call(*c, {{"cmd", "live"}}, false);
            if (c->json) {
                std::printf("%s\n", r["live"].dump(2).c_str());
                return;
            }
            std::printf("%-36s %12s %-9s %-12s %10s\n", "channel", "value", "unit", "quality", "age s");
            for (const auto& [key, ch] : r["live"].items()) {
                const auto& v = ch["value"];
                std::printf("%-36s %12s %-9s %-12s %10.1f\n", key.c_str(),
                            v.is_number() ? fmt::format("{:.4g}", v.get<double>()).c_str() : "—", ch.value("unit", "").c_str(),
                            ch.value("quality", "").c_str(), ch.value("age_s", 0.0));
            }
        });
    }
    if (building("campaigns")) {
        auto db = std::make_shared<std::string>("manikind.db");
        auto json = std::make_shared<bool>(false);
        auto* cmd = app.add_subcommand("campaigns", "The campaigns in a daemon's database: name, created, trials done/total, state");
        cmd->add_option("--db", *db, "The daemon's database")->capture_default_str();
        cmd->add_flag("--json", *json, "Print one JSON array");
        cmd->callback([db, json] {
            auto database = recorder::Database::open_read_only(*db);
            nlohmann::json out = nlohmann::json::array();
            for (const auto& row : database.campaigns()) {
                // Trials are created as they start, so the total comes from the plan: cases x replicates.
                const auto definition = nlohmann::json::parse(row.definition_json, nullptr, false);
                const int replicates = definition.is_object() ? definition.value("replicates", 1) : 1;
                const auto cases = database.cases(row.id).size();
                int done = 0, failed = 0;
                for (const auto& t : database.trials(row.id)) {
                    if (t.state == "done") ++done;
                    else if (recorder::is_terminal_trial_state(t.state)) ++failed;
                }
                out.push_back({{"name", row.name}, {"created_utc", utc_text(row.created_utc_ns)},
                               {"created_utc_ns", row.created_utc_ns}, {"trials_done", done}, {"trials_failed_or_aborted", failed},
                               {"trials_total", static_cast<int>(cases) * replicates}, {"state", row.state}});
            }
            if (*json) {
                std::printf("%s\n", out.dump(2).c_str());
                return;
            }
            if (out.empty()) {
                std::printf("%s: no campaigns\n", db->c_str());
                return;
            }
            std::printf("%-28s %-20s %11s %6s  %s\n", "campaign", "created (UTC)", "done/total", "failed", "state");
            for (const auto& r : out)
                std::printf("%-28s %-20s %5d/%-5d %6d  %s\n", r["name"].get<std::string>().c_str(),
                            r["created_utc"].get<std::string>().c_str(), r["trials_done"].get<int>(), r["trials_total"].get<int>(),
                            r["trials_failed_or_aborted"].get<int>(), r["state"].get<std::string>().c_str());
        });
    }
    if (building("log")) {
        auto db = std::make_shared<std::string>("manikind.db");
        auto wanted = std::make_shared<std::vector<std::string>>();
        auto last_min = std::make_shared<double>(60.0);
        auto json = std::make_shared<bool>(false);
        auto* cmd = app.add_subcommand("log", "The idle log: readings recorded outside trials ([lab] idle_log_period_s), "
                                              "as CSV (utc, channel, value, unit, quality)");
        cmd->add_option("--db", *db, "The daemon's database")->capture_default_str();
        cmd->add_option("--channel", *wanted, "DEVICE/CHANNEL, e.g. chamber/air_temp_pv_c (repeatable; default: every channel)");
        cmd->add_option("--last-min", *last_min, "Minutes back from the newest reading")->capture_default_str()->check(CLI::PositiveNumber);
        cmd->add_flag("--json", *json, "One JSON object per channel instead of CSV");
        cmd->callback([db, wanted, last_min, json] {
            auto database = recorder::Database::open_read_only(*db);
            std::vector<recorder::ChannelRow> chosen;
            for (const auto& ch : database.channels()) {
                const std::string key = ch.device_name + "/" + ch.name;
                if (wanted->empty() || std::find(wanted->begin(), wanted->end(), key) != wanted->end()) chosen.push_back(ch);
            }
            for (const auto& w : *wanted)
                if (std::none_of(chosen.begin(), chosen.end(), [&](const auto& ch) { return ch.device_name + "/" + ch.name == w; }))
                    throw UserError(fmt::format("--channel {}: no such channel in {} (see `manikin live` for names)", w, *db));
            // The window ends at the newest idle reading; the log is keyed by time, so only the
            // window is read.
            const std::int64_t newest = database.newest_idle_utc_ns().value_or(0);
            const auto since = newest - static_cast<std::int64_t>(*last_min * 60e9);
            std::vector<std::vector<recorder::SampleRow>> rows;
            for (const auto& ch : chosen) rows.push_back(database.idle_samples(ch.id, since));
            nlohmann::json out = nlohmann::json::array();
            if (!*json) std::printf("utc_s,channel,value,unit,quality\n");
            for (std::size_t i = 0; i < chosen.size(); ++i) {
                const std::string key = chosen[i].device_name + "/" + chosen[i].name;
                nlohmann::json points = nlohmann::json::array();
                for (const auto& r : rows[i]) {
                    if (r.utc_ns < since) continue;
                    if (*json)
                        points.push_back({static_cast<double>(r.utc_ns) * 1e-9, std::isnan(r.value) ? nlohmann::json(nullptr) : nlohmann::json(r.value), r.quality});
                    else
                        std::printf("%.3f,%s,%.6g,%s,%d\n", static_cast<double>(r.utc_ns) * 1e-9, key.c_str(), r.value,
                                    chosen[i].unit.c_str(), r.quality);
                }
                if (*json) out.push_back({{"channel", key}, {"unit", chosen[i].unit}, {"points_utc_s_value_quality", points}});
            }
            if (*json) std::printf("%s\n", out.dump().c_str());
        });
    }
    if (building("report")) {
        struct ReportOptions {
            std::string db = "manikind.db", campaign, out, trial;
            bool force = false, json = false;
        };
        auto o = std::make_shared<ReportOptions>();
        auto* cmd = app.add_subcommand("report", "Write a printable campaign (or trial) report from the database: conditions, "
                                                 "stage times, steady-state verdicts, fluxes with 95 % intervals, notes, alarms");
        cmd->add_option("campaign", o->campaign, "Campaign name (manikin campaigns --db FILE lists them)")->required();
        cmd->add_option("out", o->out, "The HTML file to write (new; print it from a browser, or save it as PDF there)")->required();
        cmd->add_option("--db", o->db, "The daemon's database")->capture_default_str();
        cmd->add_option("--trial", o->trial, "One trial only, by its id in the export (c01-r2)");
        cmd->add_flag("--force", o->force, "Replace an existing report file (never a database, a device or a folder)");
        cmd->add_flag("--json", o->json, "Print what was written as one JSON object");
        cmd->footer("A running campaign is reported as far as it has gone (its running trial marked so).\n"
                    "Example: manikin report --db lab.db validation-2026 validation-2026.html");
        cmd->callback([o] {
            ExportTarget target(o->out, ExportShape::file, o->force, {o->db});
            auto db = recorder::Database::open_read_only(o->db);
            const auto c = campaign_from_database(db, o->campaign, 5.0, true);
            const auto result = analysis::analyze_campaign(c);
            analysis::LabReportInput in;
            in.campaign = &c;
            in.result = &result;
            in.only_trial = o->trial;
            in.generated_utc = analysis::iso_utc_ms(
                std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
            const auto campaign_id = db.find_campaign(o->campaign).value();
            std::map<std::int64_t, int> case_number;
            for (const auto& cs : db.cases(campaign_id)) case_number[cs.id] = case_number_of(cs);
            std::int64_t first_utc = 0, last_utc = 0;
            for (const auto& row : db.campaigns())
                if (row.id == campaign_id) first_utc = row.created_utc_ns;
            for (const auto& t : db.trials(campaign_id)) {
                analysis::ReportTrial rt;
                rt.id = exported_trial_id(case_number[t.case_id], t.replicate);
                rt.database_id = t.id;
                rt.state = recorder::is_terminal_trial_state(t.state) ? t.state : "running";
                rt.reason = t.reason;
                for (const auto& e : db.events(t.id)) {
                    if (e.kind == "stage") rt.stages.push_back({e.utc_ns, e.severity, e.kind, e.message});
                    if (e.severity == "warn" || e.severity == "error") rt.alarms.push_back({e.utc_ns, e.severity, e.kind, e.message});
                    last_utc = std::max(last_utc, e.utc_ns);
                }
                in.trials.push_back(std::move(rt));
            }
            if (!o->trial.empty() && std::none_of(in.trials.begin(), in.trials.end(), [&](const auto& t) { return t.id == o->trial; }))
                throw UserError(fmt::format("--trial {}: no such trial in '{}' (ids are c<case>-r<replicate>, as the export names them)",
                                            o->trial, o->campaign),
                                "bad_usage");
            // The lab's alarms of no trial while the campaign ran (a device lost between trials, the disk).
            for (const auto& e : db.events(std::nullopt))
                if (!e.trial_id && (e.severity == "warn" || e.severity == "error") && e.utc_ns >= first_utc && (last_utc == 0 || e.utc_ns <= last_utc))
                    in.campaign_alarms.push_back({e.utc_ns, e.severity, e.kind, e.message});
            in.lab_name = c.provenance.count("lab") ? c.provenance.at("lab") : std::string("manikind");
            {
                std::ofstream out(target.staging(), std::ios::binary | std::ios::trunc);
                out << analysis::lab_report_html(in);
                out.flush();
                if (!out) throw UserError(fmt::format("{}: write failed", o->out), "write_failed");
            }
            target.commit();
            if (o->json)
                std::printf("%s\n", nlohmann::json{{"campaign", o->campaign}, {"path", o->out}, {"format", "html"},
                                                   {"trial", o->trial.empty() ? nlohmann::json(nullptr) : nlohmann::json(o->trial)},
                                                   {"trials", in.trials.size()}}.dump(2).c_str());
            else
                std::printf("%s report of '%s' written to %s\n", o->trial.empty() ? "campaign" : "trial", o->campaign.c_str(), o->out.c_str());
        });
    }
    if (building("export")) {
        struct ExportOptions {
            std::string db = "manikind.db", campaign, out, format, archive, lab;
            bool json = false, force = false;
        };
        auto o = std::make_shared<ExportOptions>();
        auto* cmd = app.add_subcommand("export", "Write a recorded campaign from the database: every channel with its unit and "
                                                 "quality, UTC beside trial time (CSV folder or one HDF5 file)");
        cmd->add_option("campaign", o->campaign, "Campaign name (manikin campaigns --db FILE lists them)")->required();
        cmd->add_option("out", o->out, "Output: a folder for csv (campaign.json + trials/*.csv), a file for hdf5")->required();
        auto* db_option = cmd->add_option("--db", o->db, "The daemon's database")->capture_default_str();
        auto* archive_option = cmd->add_option("--archive", o->archive, "Read the campaign from the PostgreSQL archive "
                                                                        "instead (a libpq conninfo, docs/archive.md)");
        cmd->add_option("--lab", o->lab, "With --archive: the lab id the campaign was pushed under")->needs(archive_option);
        archive_option->excludes(db_option);
        cmd->add_option("--format", o->format, "csv: manikin-recording/2, read by manikin analyze, pandas, MATLAB; "
                                               "hdf5: manikin-hdf5/1 with the analysis beside the data. Default: hdf5 for an "
                                               "output named *.h5, *.hdf5 or *.he5, else csv")
            ->check(CLI::IsMember({"csv", "hdf5"}));
        cmd->add_flag("--json", o->json, "Print what was written as one JSON object");
        cmd->add_flag("--force", o->force, "Replace an existing output file, or a folder holding an earlier export (never a "
                                           "database, a device or a folder with other files)");
        cmd->footer(std::string("The formats are in docs/formats.md (section 1 and \"HDF5\"). Heat flux: ") + analysis::kHeatFluxSign +
                    ".\nExamples:\n  manikin export --db lab.db validation-2026 recordings/validation-2026\n"
                    "  manikin export --db lab.db validation-2026 validation-2026.h5 --format hdf5\n"
                    "  manikin export --archive postgresql://archive.example/manikin --lab lab-3 validation-2026 out");
        cmd->callback([o] {
            // The format follows the output's name unless told (a CSV folder named out.h5 surprised
            // every user who tried it); told csv for an HDF5 name is a slip, refused.
            {
                std::string ext = std::filesystem::path(o->out).extension().string();
                std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
                const bool hdf5_name = ext == ".h5" || ext == ".hdf5" || ext == ".he5";
                if (o->format.empty()) o->format = hdf5_name ? "hdf5" : "csv";
                else if (o->format == "csv" && hdf5_name)
                    throw UserError(fmt::format("{}: --format csv writes a folder; this name says HDF5 (leave --format out, "
                                                "or name a folder)",
                                                o->out),
                                    "bad_usage");
            }
            // The output is checked before anything is read: an export never writes over its
            // input, a database, a device or (without --force) anything at all (issue 30).
            std::vector<std::filesystem::path> inputs;
            if (o->archive.empty()) inputs.emplace_back(o->db);
            ExportTarget target(o->out, o->format == "hdf5" ? ExportShape::file : ExportShape::folder, o->force, inputs);
            // One trial at a time: read, written, freed (memory: one trial's, whatever the
            // campaign's length). From the archive: pulled into a temporary file first, then read
            // from it the same way.
            std::optional<recorder::Database> database;
            std::optional<PulledCampaign> pulled;
            if (!o->archive.empty()) {
                if (o->lab.empty()) throw UserError("--archive needs --lab <id>: the lab the campaign was pushed under");
                pulled.emplace(o->archive, o->lab, o->campaign);
            } else {
                database.emplace(recorder::Database::open_read_only(o->db));
            }
            // A trial still acquiring goes too, up to its last committed reading, marked partial.
            CampaignReader reader(pulled ? pulled->database() : *database, o->campaign, 5.0, true);
            analysis::Campaign& c = reader.campaign();
            if (pulled) c.provenance["database"] = pulled->source();
            c.provenance["exported_utc"] = analysis::iso_utc_ms(
                std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
            // Progress on stderr where a person watches: the trial count as it goes.
            const bool show_progress = !o->json && ::isatty(STDERR_FILENO) != 0;
            const ExportProgress progress = [&](std::size_t done, std::size_t all) {
                if (show_progress) std::fprintf(stderr, "\rexporting: %zu of %zu trials%s", done, all, done == all ? "\n" : "");
            };
            ExportCounts counts;
            try {
                if (o->format == "hdf5") {
                    // The analysis beside the data, from each trial's summary as it passes.
                    Hdf5CampaignFile file(target.staging(), c);
                    std::vector<analysis::TrialResult> summaries;
                    counts = stream_trials(
                        reader,
                        [&](std::size_t s, analysis::TrialData&& data, bool again) {
                            const analysis::Trial trial{c.trials[s].info, std::move(data)};
                            // The summary once; a trial written again only gains an empty column.
                            if (!again) summaries.push_back(analysis::summarize_trial(trial, c.zone_map));
                            file.write_trial(c, trial.info, trial.data);
                        },
                        progress);
                    file.finish(analysis::aggregate_trials(c, summaries));
                } else {
                    counts = export_campaign_csv(reader, target.staging(), progress);
                }
            } catch (const analysis::InputError& e) {  // a write failed (a full disk): named, exit 2
                throw UserError(fmt::format("{}: the export was not written: {}", o->out, e.what()), "write_failed");
            } catch (const UserError& e) {
                throw UserError(fmt::format("{}: the export was not written: {}", o->out, e.what()), e.code(), e.status());
            }
            const std::size_t rows = counts.rows;
            target.commit();
            if (o->json) {
                const nlohmann::json doc{{"campaign", o->campaign}, {"format", o->format == "hdf5" ? kHdf5Format : analysis::kRecordingFormat},
                                         {"path", o->out}, {"trials", c.trials.size()}, {"rows", rows},
                                         {"channels", c.channels.size()}, {"provenance", c.provenance}};
                std::printf("%s\n", doc.dump(2).c_str());
            } else {
                std::printf("%zu trials of '%s' (%zu rows, %zu recorded channels) written to %s\n", c.trials.size(),
                            o->campaign.c_str(), rows, c.channels.size(), o->out.c_str());
                for (std::size_t s = 0; s < c.trials.size(); ++s)
                    if (c.trials[s].info.partial)
                        std::printf("trial %s is still acquiring: exported up to its last committed reading (%.0f min), marked "
                                    "\"partial\"\n",
                                    c.trials[s].info.id.c_str(), s < counts.last_t_s.size() ? counts.last_t_s[s] / 60.0 : 0.0);
                if (o->format == "csv") std::printf("analyse with: manikin analyze %s\n", o->out.c_str());
            }
        });
    }
}

}  // namespace manikind::cli
