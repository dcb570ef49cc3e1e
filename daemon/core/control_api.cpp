#include "daemon/core/control_api.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <random>

#include "daemon/core/user_error.hpp"

namespace manikind {

namespace {

nlohmann::json fail(const std::string& why) { return {{"ok", false}, {"error", why}}; }

const std::map<std::string, bool>& commands() {  // name -> mutating
    static const std::map<std::string, bool> c = {{"status", false}, {"live", false},          {"results", false},
                                                  {"start_campaign", true}, {"abort", true}, {"pause", true},
                                                  {"resume", true},  {"set_chamber", true},  {"shutdown", true}};
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

nlohmann::json handle_request(LabDaemon& daemon, const ControlOptions& o, const std::string& line, bool& shutdown) {
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
            if (!name) return fail("\"campaign\": expected a campaign name (none has run yet)");
            return {{"ok", true}, {"campaign", *name}, {"results", daemon.results_json(*name)}};
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
        if (cmd == "abort") return done(daemon.abort(text("reason").value_or("aborted by the operator")));
        if (cmd == "pause") return done(daemon.pause());
        if (cmd == "resume") return done(daemon.resume());
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

ControlServer::ControlServer(LabDaemon& daemon, ControlOptions options) : daemon_(daemon), o_(std::move(options)) {}
ControlServer::~ControlServer() { stop(); }

void ControlServer::start() {
    unix_fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    const std::string path = o_.socket_path.string();
    if (path.size() >= sizeof addr.sun_path) throw UserError(fmt::format("socket path too long: {}", path));
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    ::unlink(path.c_str());  // a stale socket from a killed daemon
    const mode_t old_mask = ::umask(0117);  // created 0660: owner and group only
    const int rc = ::bind(unix_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
    ::umask(old_mask);
    if (rc != 0 || ::listen(unix_fd_, 16) != 0)
        throw UserError(fmt::format("cannot listen on {}: {}", path, std::strerror(errno)));
    ::chmod(path.c_str(), 0660);
    if (o_.tcp_port > 0) {
        tcp_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        int one = 1;
        ::setsockopt(tcp_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        sockaddr_in in{};
        in.sin_family = AF_INET;
        in.sin_addr.s_addr = htonl(INADDR_LOOPBACK);  // never any other interface
        in.sin_port = htons(static_cast<std::uint16_t>(o_.tcp_port));
        if (::bind(tcp_fd_, reinterpret_cast<sockaddr*>(&in), sizeof in) != 0 || ::listen(tcp_fd_, 16) != 0)
            throw UserError(fmt::format("cannot listen on 127.0.0.1:{}: {}", o_.tcp_port, std::strerror(errno)));
        bound_tcp_port_ = o_.tcp_port;
    }
    if (::pipe2(wake_, O_CLOEXEC) != 0) throw UserError("pipe failed");
    thread_ = std::thread([this] { serve(); });
}

void ControlServer::stop() {
    if (!thread_.joinable()) return;
    const char b = 'x';
    [[maybe_unused]] auto n = ::write(wake_[1], &b, 1);
    thread_.join();
    for (int fd : {unix_fd_, tcp_fd_, wake_[0], wake_[1]})
        if (fd >= 0) ::close(fd);
    ::unlink(o_.socket_path.c_str());
}

void ControlServer::serve() {
    struct Client {
        int fd;
        std::string buffer;
    };
    std::vector<Client> clients;
    for (;;) {
        std::vector<pollfd> fds = {{wake_[0], POLLIN, 0}, {unix_fd_, POLLIN, 0}};
        if (tcp_fd_ >= 0) fds.push_back({tcp_fd_, POLLIN, 0});
        const std::size_t first_client = fds.size();
        for (const auto& c : clients) fds.push_back({c.fd, POLLIN, 0});
        if (::poll(fds.data(), fds.size(), -1) < 0) {
            if (errno == EINTR) continue;
            return;
        }
        if (fds[0].revents) return;
        for (std::size_t i = 1; i < first_client; ++i)
            if (fds[i].revents & POLLIN) {
                const int c = ::accept4(fds[i].fd, nullptr, nullptr, SOCK_CLOEXEC);
                if (c >= 0) clients.push_back({c, {}});
            }
        std::vector<int> closed;
        for (std::size_t i = first_client; i < fds.size(); ++i) {
            if (!fds[i].revents) continue;
            Client& c = clients[i - first_client];
            char buf[4096];
            const ssize_t n = ::read(c.fd, buf, sizeof buf);
            if (n <= 0) {
                closed.push_back(c.fd);
                continue;
            }
            c.buffer.append(buf, static_cast<std::size_t>(n));
            bool drop = false;
            for (auto nl = c.buffer.find('\n'); nl != std::string::npos; nl = c.buffer.find('\n')) {
                const std::string line = c.buffer.substr(0, nl);
                c.buffer.erase(0, nl + 1);
                bool shutdown = false;
                const std::string reply = handle_request(daemon_, o_, line, shutdown).dump() + "\n";
                // Flag before replying: a client that reads "ok" must find the shutdown requested.
                if (shutdown) shutdown_ = true;
                [[maybe_unused]] auto w = ::write(c.fd, reply.data(), reply.size());
            }
            if (c.buffer.size() > o_.max_message_bytes) {  // oversized: refuse and hang up
                const std::string reply =
                    fail(fmt::format("message over the limit of {} bytes; connection closed", o_.max_message_bytes)).dump() + "\n";
                [[maybe_unused]] auto w = ::write(c.fd, reply.data(), reply.size());
                drop = true;
            }
            if (drop) closed.push_back(c.fd);
        }
        for (int fd : closed) {
            ::close(fd);
            std::erase_if(clients, [fd](const Client& c) { return c.fd == fd; });
        }
    }
}

nlohmann::json call_daemon(const std::filesystem::path& socket_path, const nlohmann::json& request) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    const std::string path = socket_path.string();
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
        const std::string why = std::strerror(errno);
        ::close(fd);
        throw UserError(fmt::format("cannot reach the daemon at {}: {} (is manikind running? --socket)", path, why));
    }
    const std::string msg = request.dump() + "\n";
    [[maybe_unused]] auto w = ::write(fd, msg.data(), msg.size());
    std::string reply;
    char buf[65536];
    for (;;) {
        const ssize_t n = ::read(fd, buf, sizeof buf);
        if (n <= 0) break;
        reply.append(buf, static_cast<std::size_t>(n));
        if (!reply.empty() && reply.back() == '\n') break;
    }
    ::close(fd);
    const auto j = nlohmann::json::parse(reply, nullptr, false);
    if (j.is_discarded()) throw UserError("the daemon's reply is not JSON: " + reply.substr(0, 200));
    return j;
}

std::string read_token_file(const std::filesystem::path& socket_path) {
    std::ifstream in(socket_path.string() + ".token");
    std::string token;
    std::getline(in, token);
    return token;
}

std::string load_or_create_token(const std::string& configured, const std::filesystem::path& socket_path) {
    if (!configured.empty()) return configured;
    std::random_device rd;
    std::string token;
    for (int i = 0; i < 32; ++i) token += "0123456789abcdef"[rd() % 16];
    const std::string file = socket_path.string() + ".token";
    const int fd = ::open(file.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) throw UserError(fmt::format("cannot write the API token to {}: {}", file, std::strerror(errno)));
    [[maybe_unused]] auto w = ::write(fd, (token + "\n").data(), token.size() + 1);
    ::close(fd);
    return token;
}

}  // namespace manikind
