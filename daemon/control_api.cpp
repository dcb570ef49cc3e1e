#include "daemon/control_api.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/random.h>
#include <sys/un.h>
#include <unistd.h>

#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <chrono>

#include "daemon/config.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace {

nlohmann::json fail(const std::string& why) { return {{"ok", false}, {"error", why}}; }

const std::map<std::string, bool>& commands() {  // name -> mutating
    static const std::map<std::string, bool> c = {{"status", false}, {"live", false},          {"results", false},
                                                  {"start_campaign", true}, {"abort", true}, {"pause", true},
                                                  {"resume", true},  {"continue", true}, {"set_chamber", true},  {"shutdown", true},
                                                  {"alarms", false}, {"ack_alarm", true}, {"campaign_outcome", false},
                                                  {"alarm_history", false}, {"shelve_alarm", true}, {"unshelve_alarm", true},
                                                  {"note", true}, {"notes", false}};
    return c;
}

// Constant-time comparison: the token is a secret.
bool same_token(const std::string& a, const std::string& b) {
    if (a.size() != b.size()) return false;
    unsigned char diff = 0;
    for (std::size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ b[i]);
    return diff == 0;
}

}  // namespace

nlohmann::json handle_request(LabDaemon& daemon, const ControlOptions& o, const std::string& line, bool& shutdown,
                              const RequestOrigin& origin) {
    if (line.size() > o.max_message_bytes)
        return fail(fmt::format("message of {} bytes is over the limit of {} bytes", line.size(), o.max_message_bytes));
    const nlohmann::json req = nlohmann::json::parse(line, nullptr, false);
    if (req.is_discarded()) return fail("not valid JSON");
    if (!req.is_object()) return fail("expected a JSON object");
    if (!req.contains("cmd") || !req["cmd"].is_string()) return fail("missing \"cmd\" (a string)");
    const std::string cmd = req["cmd"].get<std::string>();
    const auto known = commands().find(cmd);
    if (known == commands().end()) {
        std::string list;
        for (const auto& [name, m] : commands()) list += (list.empty() ? "" : ", ") + name;
        return fail(fmt::format("unknown command '{}' (known: {})", cmd, list));
    }
    if (known->second) {
        if (o.token.empty()) return fail("mutating commands are disabled: no token is configured");
        if (!req.contains("token") || !req["token"].is_string() || !same_token(req["token"].get<std::string>(), o.token))
            return fail("wrong or missing token");
    }
    auto number = [&](const char* key) -> std::optional<double> {
        if (!req.contains(key) || !req[key].is_number()) return std::nullopt;
        return req[key].get<double>();
    };
    auto text = [&](const char* key) -> std::optional<std::string> {
        if (!req.contains(key) || !req[key].is_string()) return std::nullopt;
        return req[key].get<std::string>();
    };
    auto done = [](const std::string& why) { return why.empty() ? nlohmann::json{{"ok", true}} : fail(why); };
    try {
        if (cmd == "status") return {{"ok", true}, {"status", daemon.status_json()}};
        if (cmd == "live") return {{"ok", true}, {"live", daemon.live_json()}};
        if (cmd == "results") {
            auto name = text("campaign");
            if (!name) name = daemon.last_campaign();
            // Nothing to show yet is an answer, not a refusal: "results" is null and "note" says why.
            if (!name) return {{"ok", true}, {"campaign", nullptr}, {"results", nullptr}, {"note", "no campaign has run yet"}};
            auto results = daemon.latest_results_json(*name);
            if (!results)
                return {{"ok", true}, {"campaign", *name}, {"results", nullptr},
                        {"note", fmt::format("campaign '{}' has no results yet", *name)}};
            return {{"ok", true}, {"campaign", *name}, {"results", std::move(*results)}};
        }
        if (cmd == "start_campaign") {
            CampaignPlan plan;
            if (const auto b = text("builtin")) {
                if (*b != "table-s3") return fail("\"builtin\": the only built-in campaign is \"table-s3\"");
                const auto name = text("name");
                if (!name || name->empty()) return fail("\"name\": expected the campaign's name (a string)");
                plan = table_s3_plan(*name);
            } else if (const auto t = text("plan_toml")) {
                plan = parse_campaign_plan(*t, text("source").value_or("campaign"));
            } else {
                return fail("expected \"plan_toml\" (the campaign file's text) or \"builtin\":\"table-s3\"");
            }
            return done(daemon.start_campaign(plan));
        }
        if (cmd == "abort") {
            // "confirm": the running campaign's name, as typed; required from the console, checked when given.
            const auto running = daemon.running_campaign();
            if (!running) return fail("no campaign is running");
            const auto confirm = text("confirm");
            if (origin.abort_needs_confirmation && !confirm)
                return fail(fmt::format("\"confirm\": type the running campaign's name ('{}') to abort it", *running));
            if (confirm && *confirm != *running)
                return fail(fmt::format("\"confirm\": '{}' is not the running campaign ('{}'): nothing aborted",
                                        printable(*confirm), *running));
            auto reason = text("reason").value_or("");
            if (reason.empty()) reason = "no reason given";
            if (reason.size() > 500) reason.resize(500);
            return done(daemon.abort(printable(reason), origin.who));
        }
        if (cmd == "campaign_outcome") {
            const auto name = text("campaign");
            if (!name) return fail("\"campaign\": expected the campaign's name (a string)");
            return {{"ok", true}, {"outcome", daemon.campaign_outcome_json(*name)}};
        }
        if (cmd == "alarms") return {{"ok", true}, {"alarms", daemon.alarms_json()}};
        if (cmd == "note") {
            const auto name = text("campaign");
            if (!name) return fail("\"campaign\": expected the campaign's name (a string)");
            const auto body = text("text");
            if (!body) return fail("\"text\": expected the note's text (a string)");
            std::optional<std::int64_t> trial;
            if (req.contains("trial") && req["trial"].is_string()) {
                // The export's name of a trial ("c03-r2"), as the lab reads it in every file and report.
                const auto label = text("trial");
                if (!label) return fail("\"trial\": expected a trial's id or its name (c03-r2)");
                auto found = daemon.trial_by_label(*name, *label);
                if (const auto* why = std::get_if<std::string>(&found)) return fail(*why);
                trial = std::get<std::int64_t>(found);
            } else if (req.contains("trial") && !req["trial"].is_null()) {
                const auto t = number("trial");
                if (!t || *t != std::trunc(*t) || *t < 1 || *t > 9e15)
                    return fail("\"trial\": expected a trial's id (a whole number) or its name (c03-r2)");
                trial = static_cast<std::int64_t>(*t);
            }
            const std::string kind = text("kind").value_or("comment");
            const std::string author = text("author").value_or(origin.who);
            return done(daemon.add_note(*name, trial, kind, *body, author));
        }
        if (cmd == "notes") {
            const auto name = text("campaign");
            if (!name) return fail("\"campaign\": expected the campaign's name (a string)");
            return {{"ok", true}, {"notes", daemon.notes_json(*name)}};
        }
        if (cmd == "alarm_history") return {{"ok", true}, {"alarms", daemon.alarm_history_json()}};
        if (cmd == "ack_alarm" || cmd == "shelve_alarm" || cmd == "unshelve_alarm") {
            const auto id = number("id");
            // Bounded before the conversion: a double beyond int64 (1e300) makes it undefined.
            if (!id || *id != std::trunc(*id) || std::fabs(*id) > 9e15)
                return fail("\"id\": expected the alarm's id (a whole number)");
            const auto alarm = static_cast<std::int64_t>(*id);
            if (cmd == "ack_alarm") return done(daemon.acknowledge_alarm(alarm, origin.who));
            if (cmd == "unshelve_alarm") return done(daemon.unshelve_alarm(alarm, origin.who));
            const auto duration = number("duration_s");
            if (!duration) return fail("\"duration_s\": expected the shelf's length in seconds (at most 8 h)");
            return done(daemon.shelve_alarm(alarm, *duration, origin.who));
        }
        if (cmd == "pause") return done(daemon.pause());
        if (cmd == "resume") return done(daemon.resume());
        if (cmd == "continue") return done(daemon.operator_continue(origin.who));
        if (cmd == "set_chamber") {
            const auto t = number("chamber_temp_c"), rh = number("chamber_rh_pct");
            if (!t || !rh) return fail("\"chamber_temp_c\" and \"chamber_rh_pct\": expected numbers");
            return done(daemon.set_chamber(*t, *rh));
        }
        if (cmd == "shutdown") {
            shutdown = true;
            return {{"ok", true}};
        }
    } catch (const UserError& e) {
        return fail(e.what());
    }
    return fail("unhandled command");
}

std::string load_or_create_token(const std::string& configured, const std::filesystem::path& socket_path) {
    if (!configured.empty()) {
        if (const auto why = config::token_problem(configured); !why.empty()) throw UserError("[api] token: " + why);
        return configured;
    }
    unsigned char bytes[32];
    for (std::size_t got = 0; got < sizeof bytes;) {
        const ssize_t n = ::getrandom(bytes + got, sizeof bytes - got, 0);
        if (n < 0 && errno != EINTR) throw UserError(fmt::format("cannot make an API token: getrandom: {}", std::strerror(errno)));
        if (n > 0) got += static_cast<std::size_t>(n);
    }
    std::string token;
    for (unsigned char b : bytes) token += fmt::format("{:02x}", b);

    const std::string file = socket_path.string() + ".token";
    struct stat st {};
    if (::lstat(file.c_str(), &st) == 0) {
        // Replace only our own private file; anything else is someone's mistake or a trap: say so.
        if (S_ISLNK(st.st_mode))
            throw UserError(fmt::format("{} is a symbolic link; refusing to write the API token through it (remove it)", file));
        if (!S_ISREG(st.st_mode)) throw UserError(fmt::format("{} exists and is not a regular file; remove it", file));
        if (st.st_uid != ::geteuid())
            throw UserError(fmt::format("{} belongs to user id {}, not to the daemon's user ({}); remove it", file, st.st_uid,
                                        ::geteuid()));
        if ((st.st_mode & 077) != 0)
            throw UserError(fmt::format("{} has mode {:04o}: others could read the API token; remove it (the daemon "
                                        "writes a fresh one, mode 0600)",
                                        file, st.st_mode & 07777));
        if (::unlink(file.c_str()) != 0)
            throw UserError(fmt::format("cannot replace the API token file {}: {}", file, std::strerror(errno)));
    }
    // O_EXCL|O_NOFOLLOW: a file or symlink that appeared since is never written through.
    const int fd = ::open(file.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
    if (fd < 0) throw UserError(fmt::format("cannot write the API token to {}: {}", file, std::strerror(errno)));
    const std::string line = token + "\n";
    const bool written = ::write(fd, line.data(), line.size()) == static_cast<ssize_t>(line.size());
    ::close(fd);
    if (!written) throw UserError(fmt::format("cannot write the API token to {}", file));
    return token;
}

}  // namespace manikind
