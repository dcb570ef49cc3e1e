// The `manikin` commands that talk to a running daemon over its control socket, and the ones that
// read its database: status, campaign run|abort|pause|resume, setpoint, trial watch, results,
// export.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "analysis/analyze.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/core/control_api.hpp"
#include "daemon/core/database_export.hpp"
#include "daemon/core/recorder/database.hpp"
#include "daemon/core/user_error.hpp"

namespace manikind::cli {

namespace {

struct Conn {
    std::string socket = "manikind.sock";
    std::string token;
    double timeout_s = 10.0;
    bool json = false;
};

void add_conn_options(CLI::App* cmd, Conn& c, bool mutating) {
    cmd->add_option("--socket", c.socket, "The daemon's control socket ([api] socket)")->capture_default_str();
    if (mutating) cmd->add_option("--token", c.token, "API token (default: read from <socket>.token, or $MANIKIND_TOKEN)");
    cmd->add_option("--timeout", c.timeout_s, "Seconds to wait for the daemon's answer before saying what it waited for")
        ->capture_default_str()
        ->check(CLI::Range(0.1, 3600.0));
    cmd->add_flag("--json", c.json, "Print the daemon's JSON reply");
}

nlohmann::json call(const Conn& c, nlohmann::json req, bool mutating) {
    if (mutating) {
        std::string token = c.token;
        if (token.empty())
            if (const char* env = std::getenv("MANIKIND_TOKEN")) token = env;
        if (token.empty()) token = read_token_file(c.socket);
        req["token"] = token;
    }
    auto reply = call_daemon(c.socket, req, c.timeout_s);
    if (!reply.value("ok", false)) throw UserError("the daemon refused: " + reply.value("error", std::string("?")));
    return reply;
}

std::string bar(double fraction, int width = 30) {
    const int filled = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * width + 0.5);
    return "[" + std::string(static_cast<std::size_t>(filled), '#') + std::string(static_cast<std::size_t>(width - filled), '.') + "]";
}

void print_status(const nlohmann::json& s) {
    std::printf("%s lab, %s clock, t = %.0f s; database %s\n", s["mode"].get<std::string>().c_str(),
                s["clock"].get<std::string>().c_str(), s["time_s"].get<double>(), s["database"].get<std::string>().c_str());
    if (s["campaign"].is_null()) std::printf("no campaign running\n");
    else
        std::printf("campaign %s: %d of %d trials done; stage %s%s\n", s["campaign"].get<std::string>().c_str(),
                    s["trials_done"].get<int>(), s["trials_total"].get<int>(), s["stage"].get<std::string>().c_str(),
                    s["paused"].get<bool>() ? " (paused)" : "");
    if (s.contains("trial")) {
        const auto& t = s["trial"];
        std::printf("trial %ld: case %d replicate %d, %.0f s in stage", t["id"].get<long>(), t["case"].get<int>(),
                    t["replicate"].get<int>(), t["stage_elapsed_s"].get<double>());
        if (t.contains("steady_progress"))
            std::printf("  steady %s %3.0f %%  worst zone range %.3f °C%s", bar(t["steady_progress"].get<double>()).c_str(),
                        100.0 * t["steady_progress"].get<double>(), t["worst_zone_range_c"].get<double>(),
                        t["steady"].get<bool>() ? "  STEADY" : "");
        std::printf("\n");
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
    std::printf("recorder: %llu samples committed, %llu dropped\n", r["committed"].get<unsigned long long>(),
                r["dropped"].get<unsigned long long>());
}

}  // namespace

void add_daemon_commands(CLI::App& app) {
    {
        auto c = std::make_shared<Conn>();
        auto* cmd = app.add_subcommand("status", "The running daemon: campaign, trial stage, devices and their counters");
        add_conn_options(cmd, *c, false);
        cmd->callback([c] {
            const auto r = call(*c, {{"cmd", "status"}}, false);
            if (c->json) std::printf("%s\n", r["status"].dump(2).c_str());
            else print_status(r["status"]);
        });
    }
    {
        auto* campaign = app.add_subcommand("campaign", "Start, abort, pause or resume a campaign on the running daemon");
        campaign->require_subcommand(1);
        auto c = std::make_shared<Conn>();
        auto file = std::make_shared<std::string>();
        auto* run = campaign->add_subcommand("run", "Queue a campaign: a TOML file (cases x replicates), or builtin:table-s3");
        run->add_option("file", *file, "Campaign file (see config/campaign-example.toml) or builtin:table-s3")->required();
        add_conn_options(run, *c, true);
        run->callback([c, file] {
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
            if (c->json) std::printf("{\"ok\":true}\n");
            else std::printf("campaign queued; follow it with `manikin trial watch`\n");
        });
        for (const char* name : {"abort", "pause", "resume"}) {
            auto* sub = campaign->add_subcommand(name, fmt::format("{} the running campaign", name));
            add_conn_options(sub, *c, true);
            sub->callback([c, name] {
                call(*c, {{"cmd", name}}, true);
                std::printf("%s\n", c->json ? "{\"ok\":true}" : "done");
            });
        }
    }
    {
        auto c = std::make_shared<Conn>();
        auto temp = std::make_shared<double>(), rh = std::make_shared<double>();
        auto* cmd = app.add_subcommand("setpoint", "Set the chamber's temperature and humidity (checked against [safety])");
        cmd->add_option("--chamber-temp", *temp, "°C")->required();
        cmd->add_option("--chamber-rh", *rh, "%")->required();
        add_conn_options(cmd, *c, true);
        cmd->callback([c, temp, rh] {
            call(*c, {{"cmd", "set_chamber"}, {"chamber_temp_c", *temp}, {"chamber_rh_pct", *rh}}, true);
            std::printf("chamber setpoints sent\n");
        });
    }
    {
        auto c = std::make_shared<Conn>();
        auto once = std::make_shared<bool>(false);
        auto* trial = app.add_subcommand("trial", "Follow the running trial");
        trial->require_subcommand(1);
        auto* watch = trial->add_subcommand("watch", "Live status with a progress bar toward steady state (Ctrl-C to stop)");
        add_conn_options(watch, *c, false);
        watch->add_flag("--once", *once, "Print one update and exit");
        watch->callback([c, once] {
            for (;;) {
                const auto r = call(*c, {{"cmd", "status"}}, false);
                if (c->json) std::printf("%s\n", r["status"].dump().c_str());
                else {
                    std::printf("\033[H\033[2J");
                    print_status(r["status"]);
                }
                std::fflush(stdout);
                if (*once || r["status"]["campaign"].is_null()) break;
                std::this_thread::sleep_for(std::chrono::seconds(1));
            }
        });
    }
    {
        auto c = std::make_shared<Conn>();
        auto campaign = std::make_shared<std::string>();
        auto* cmd = app.add_subcommand("results", "Whole-body heat flux per case with 95 % CIs, from the running daemon");
        cmd->add_option("--campaign", *campaign, "Campaign name (default: the last one run)");
        add_conn_options(cmd, *c, false);
        cmd->callback([c, campaign] {
            nlohmann::json req{{"cmd", "results"}};
            if (!campaign->empty()) req["campaign"] = *campaign;
            const auto r = call(*c, req, false);
            if (c->json) {
                std::printf("%s\n", r["results"].dump(2).c_str());
                return;
            }
            std::printf("campaign %s\n  case  n   Q_WB W/m²   U (95 %%)   95 %% CI\n", r["campaign"].get<std::string>().c_str());
            for (const auto& cs : r["results"]["cases"]) {
                const auto& wb = cs["whole_body"];
                std::printf("  %4d  %d  %9.2f  %9.2f   [%.2f, %.2f]\n", cs.value("case", 0), cs.value("n_replicates", 0),
                            wb.value("q_w_m2", 0.0), wb.value("U", 0.0), wb.value("ci_low_w_m2", 0.0), wb.value("ci_high_w_m2", 0.0));
            }
        });
    }
    {
        auto db = std::make_shared<std::string>("manikind.db");
        auto campaign = std::make_shared<std::string>(), dir = std::make_shared<std::string>();
        auto* cmd = app.add_subcommand("export", "Write a recorded campaign from the database in the interchange format "
                                                 "(campaign.json + trials/*.csv)");
        cmd->add_option("campaign", *campaign, "Campaign name")->required();
        cmd->add_option("dir", *dir, "Output folder")->required();
        cmd->add_option("--db", *db, "The daemon's database")->capture_default_str();
        cmd->callback([db, campaign, dir] {
            if (!std::filesystem::exists(*db)) throw UserError(fmt::format("{}: no such database", *db));
            auto database = recorder::Database::open(*db);
            const auto c = campaign_from_database(database, *campaign);
            analysis::write_campaign(*dir, c);
            std::printf("%zu trials of '%s' written to %s (analyse with: manikin analyze %s)\n", c.trials.size(),
                        campaign->c_str(), dir->c_str(), dir->c_str());
        });
    }
}

}  // namespace manikind::cli
