#include "daemon/web_server.hpp"
#include "base/guarded.hpp"

#include <cctype>
#include <sys/socket.h>

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <list>
#include <mutex>
#include <sstream>
#include <thread>

#include "analysis/zone_map.hpp"
#include "daemon/console_model.hpp"
#include "store/database.hpp"
#include "base/text.hpp"
#include "base/user_error.hpp"

namespace manikind {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using WebClock = std::chrono::steady_clock;

namespace {

// The chamber's history before this console started, from the database (read-only, its own
// connection: the daemon's lock is never held): the idle log of the five charted channels and,
// for trials that ran in the window, their samples of them, binned to `step_s`, each trial's
// chamber setpoints from its case. Errors leave the history as it is (said in the log).
std::vector<console::ChamberHistory::Point> history_from_database(const std::filesystem::path& db_path, std::int64_t since_utc_ns,
                                                                  double step_s, std::map<std::string, std::int64_t>& campaign_starts_ms) {
    constexpr double nan = std::numeric_limits<double>::quiet_NaN();
    std::map<std::int64_t, console::ChamberHistory::Point> bins;
    auto db = recorder::Database::open_read_only(db_path);
    enum Field { air, air_pv, rh, rh_pv, speed };
    const std::map<std::string, Field> wanted{{"datalogger/ee181_1.air_temp_c", air}, {"chamber/air_temp_pv_c", air_pv},
                                              {"datalogger/ee181_1.air_rh_pct", rh}, {"chamber/air_rh_pv_pct", rh_pv},
                                              {"windsonic/air_speed_m_s", speed}};
    std::map<std::int64_t, Field> channels;
    for (const auto& ch : db.channels())
        if (const auto it = wanted.find(ch.device_name + "/" + ch.name); it != wanted.end()) channels[ch.id] = it->second;
    const auto step_ns = static_cast<std::int64_t>(step_s * 1e9);
    auto put = [&](const recorder::SampleRow& r, Field f, double sp_air, double sp_rh, const char* stage) {
        if (r.utc_ns < since_utc_ns || r.quality != 0) return;
        auto [it, fresh] = bins.try_emplace(r.utc_ns / step_ns, console::ChamberHistory::Point{0.0, (r.utc_ns / step_ns) * step_ns / 1'000'000,
                                                                                                 nan, nan, sp_air, nan, nan, sp_rh, nan, stage});
        (void)fresh;
        double* slot[] = {&it->second.air_temp_c, &it->second.air_temp_pv_c, &it->second.air_rh_pct, &it->second.air_rh_pv_pct,
                          &it->second.air_speed_m_s};
        *slot[f] = r.value;
    };
    for (const auto& [id, field] : channels)
        for (const auto& r : db.idle_samples(id, since_utc_ns)) put(r, field, nan, nan, "idle");
    for (const auto& c : db.campaigns()) {
        campaign_starts_ms[c.name] = c.created_utc_ns / 1'000'000;
        std::map<std::int64_t, std::pair<double, double>> setpoints;  // case id -> chamber air, RH
        for (const auto& k : db.cases(c.id)) {
            const auto j = nlohmann::json::parse(k.conditions_json, nullptr, false);
            const auto number = [&](const char* key) {
                return j.is_object() && j.contains(key) && j[key].is_number() ? j[key].get<double>() : nan;
            };
            setpoints[k.id] = {number("chamber_temp_c"), number("chamber_rh_pct")};
        }
        for (const auto& t : db.trials(c.id)) {
            const bool in_window = (t.ended_utc_ns && *t.ended_utc_ns >= since_utc_ns) || (!t.ended_utc_ns && t.started_utc_ns);
            if (!in_window) continue;
            const auto sp = setpoints[t.case_id];
            for (const auto& [id, field] : channels)
                for (const auto& r : db.samples(t.id, id)) put(r, field, sp.first, sp.second, "trial");
        }
    }
    std::vector<console::ChamberHistory::Point> out;
    out.reserve(bins.size());
    for (auto& [bin, p] : bins) out.push_back(std::move(p));
    return out;
}

// A query value with its %XX escapes and '+' decoded (a malformed escape is kept as typed).
std::string percent_decoded(std::string_view v) {
    std::string out;
    for (std::size_t i = 0; i < v.size(); ++i) {
        if (v[i] == '+') {
            out += ' ';
        } else if (v[i] == '%' && i + 2 < v.size() && std::isxdigit(static_cast<unsigned char>(v[i + 1])) &&
                   std::isxdigit(static_cast<unsigned char>(v[i + 2]))) {
            out += static_cast<char>(std::stoi(std::string(v.substr(i + 1, 2)), nullptr, 16));
            i += 2;
        } else {
            out += v[i];
        }
    }
    return out;
}

std::chrono::nanoseconds seconds(double s) {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(s));
}

double utc_ms() {
    return static_cast<double>(std::chrono::duration_cast<std::chrono::microseconds>(
                                   std::chrono::system_clock::now().time_since_epoch())
                                   .count()) *
           1e-3;
}

bool is_loopback(const std::string& host) {
    boost::system::error_code ec;
    const auto addr = asio::ip::make_address(host, ec);
    return !ec && addr.is_loopback();
}

}  // namespace

WebOptions parse_listen(const std::string& listen, const std::string& where) {
    WebOptions o;
    const auto colon = listen.rfind(':');
    if (colon == std::string::npos || colon == 0)
        throw UserError(fmt::format("{}: '{}': expected HOST:PORT, e.g. 127.0.0.1:8470", where, listen));
    std::string host = listen.substr(0, colon);
    if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
    if (host == "localhost") host = "127.0.0.1";
    if (!is_loopback(host))
        throw UserError(fmt::format("{}: '{}': the console listens on a loopback address only (127.0.0.1 or ::1); "
                                    "reach it from another machine through an SSH tunnel",
                                    where, listen));
    const std::string port = listen.substr(colon + 1);
    char* end = nullptr;
    const long p = std::strtol(port.c_str(), &end, 10);
    if (port.empty() || *end != '\0' || p < 0 || p > 65535)
        throw UserError(fmt::format("{}: '{}': the port must be a number 0..65535 (0: any free port)", where, listen));
    o.host = host;
    o.port = static_cast<int>(p);
    return o;
}

struct WebServer::Impl {
    struct WsSession;
    struct HttpSession;

    Impl(LabDaemon& d, ControlOptions a, WebOptions w) : daemon(d), api(std::move(a)), o(std::move(w)), history(o.history_s) {}

    LabDaemon& daemon;
    ControlOptions api;
    WebOptions o;
    // Reset in stop(), after the timers and acceptor: pending handlers (and the sessions they
    // keep alive) die while the rest of the server still exists.
    std::unique_ptr<asio::io_context> io = std::make_unique<asio::io_context>();
    std::optional<tcp::acceptor> acceptor;
    std::optional<asio::steady_timer> push_timer, tick_timer;
    std::thread thread;
    int bound_port = 0;
    std::atomic<bool> shutdown{false};
    std::atomic<bool> sample_pending{false};
    std::atomic<double> pending_since_utc_ms{0};  // wall time the oldest unsent sample reached the daemon
    std::size_t clients = 0;  // HTTP and WebSocket sessions (server thread only)
    std::list<std::weak_ptr<WsSession>> sockets;
    WebClock::time_point last_push{};
    bool push_scheduled = false;
    console::DeviceSeverity severity;
    console::ChamberHistory history;
    // The history before this console started, read from the database on a thread of its own.
    std::thread seeder;
    std::mutex seed_lock;
    std::condition_variable seed_done;
    bool seeded = false;
    std::vector<std::string> allowed_hosts;  // Host header values this server answers to

    // "127.0.0.1:8470", "[::1]:8470": how a browser names this server (URL and Host header).
    std::string authority(int port) const {
        const bool v6 = o.host.find(':') != std::string::npos;
        return fmt::format("{}{}{}:{}", v6 ? "[" : "", o.host, v6 ? "]" : "", port);
    }
    void allow_hosts_for(int port) { allowed_hosts = {authority(port), fmt::format("localhost:{}", port)}; }

    // --- what the page reads ------------------------------------------------------------
    nlohmann::json status() {
        auto s = daemon.status_json();
        if (s.contains("devices")) severity.annotate(s["devices"], std::chrono::duration<double>(WebClock::now().time_since_epoch()).count());
        return s;
    }

    // The charts run on the lab's clock, the one its records are stamped with: a simulated lab at
    // --speed 10 charts ten minutes of its own per wall minute, and the database's history (seeded
    // below) lines up with the live points. Its monotonic reading orders the points.
    void record_history(const nlohmann::json& live, const nlohmann::json& s) {
        history.add(daemon.virtual_time_s(), daemon.lab_utc_ns() / 1'000'000, live, s);
    }

    nlohmann::json update_message() {
        auto live = daemon.live_json();
        auto s = status();
        record_history(live, s);
        const bool wet = s.contains("trial") && s["trial"].value("wet", false);
        auto twin = console::twin_zone_fluxes(live, wet);
        return {{"type", "update"},
                {"server_utc_ms", std::chrono::duration_cast<std::chrono::milliseconds>(
                                      std::chrono::system_clock::now().time_since_epoch())
                                      .count()},
                {"status", s},
                {"twin_q_w_m2", std::move(twin)},
                {"live", std::move(live)},
                {"alarms", daemon.alarms_json()}};
    }

    static nlohmann::json zones_json() {
        nlohmann::json a = nlohmann::json::array();
        for (const auto& z : analysis::andi35_zone_map().zones)
            a.push_back({{"zone", z.zone}, {"name", z.name}, {"segment", z.segment}, {"region", z.region}, {"area_m2", z.area_m2}});
        return a;
    }

    bool host_allowed(const http::request<http::string_body>& req) const {
        if (req.count(http::field::host) != 1) return false;  // RFC 9112 3.2: exactly one Host
        const auto host = std::string(req[http::field::host]);
        for (const auto& h : allowed_hosts)
            if (host == h) return true;
        return false;
    }
    // A browser sends Origin on cross-site requests: only this page's own origin may change state.
    bool origin_allowed(const http::request<http::string_body>& req) const {
        const auto origin = req.find(http::field::origin);
        if (origin == req.end()) return true;  // not a browser (curl, scripts): the token decides
        const std::string value(origin->value());
        for (const auto& h : allowed_hosts)
            if (value == "http://" + h) return true;
        return false;
    }

    http::response<http::string_body> reply(const http::request<http::string_body>& req, http::status code,
                                            std::string body, const char* type) {
        http::response<http::string_body> res{code, req.version()};
        res.set(http::field::server, "manikind");
        res.set(http::field::content_type, type);
        res.set(http::field::cache_control, "no-store");
        res.set("X-Content-Type-Options", "nosniff");
        res.set("X-Frame-Options", "DENY");
        // The page may talk only to this daemon: nothing is loaded or sent anywhere else.
        res.set("Content-Security-Policy",
                "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
                "base-uri 'none'; form-action 'none'; frame-ancestors 'none'");
        res.keep_alive(req.keep_alive());
        res.body() = std::move(body);
        res.prepare_payload();
        if (req.method() == http::verb::head) {  // RFC 9110 9.3.2: the GET's headers, no body
            const auto length = res.body().size();
            res.body().clear();
            res.content_length(length);
        }
        return res;
    }
    http::response<http::string_body> json_reply(const http::request<http::string_body>& req, http::status code,
                                                 const nlohmann::json& j) {
        return reply(req, code, dump_json(j), "application/json");
    }
    http::response<http::string_body> error(const http::request<http::string_body>& req, http::status code,
                                            const std::string& why) {
        return json_reply(req, code, {{"ok", false}, {"error", why}});
    }

    http::response<http::string_body> handle(const http::request<http::string_body>& req) {
        if (req.count(http::field::host) != 1)
            return error(req, http::status::bad_request,
                         fmt::format("a request carries exactly one Host header, this one {}", req.count(http::field::host)));
        if (!host_allowed(req))
            return error(req, http::status::forbidden,
                         fmt::format("Host '{}' is not this console's address", printable(std::string(req[http::field::host]))));
        const std::string target(req.target());
        if (!is_utf8(target))
            return error(req, http::status::bad_request,
                         fmt::format("the request's path is not UTF-8: {}", printable(target)));
        const std::string path = target.substr(0, target.find('?'));
        const std::string query = target.find('?') == std::string::npos ? "" : target.substr(target.find('?') + 1);
        if (req.method() == http::verb::post) {
            if (path != "/api/command") return error(req, http::status::not_found, "POST goes to /api/command only");
            if (!origin_allowed(req))
                return error(req, http::status::forbidden, "requests from another site cannot change the daemon's state");
            bool stop_now = false;
            // An abort from the console names the campaign as the operator typed it, and is recorded
            // as the console's (behind the token: whoever holds it at this browser).
            const auto r = handle_request(daemon, api, req.body(), stop_now, RequestOrigin{"the operator console", true});
            if (stop_now) shutdown = true;
            return json_reply(req, r.value("ok", false) ? http::status::ok : http::status::bad_request, r);
        }
        if (req.method() != http::verb::get && req.method() != http::verb::head)
            return error(req, http::status::method_not_allowed, "GET to read, POST /api/command to change");
        if (path == "/") {
            const auto* a = find_web_asset("/index.html");
            return reply(req, http::status::ok, std::string(a->body, a->size), a->content_type);
        }
        if (const auto* a = find_web_asset(path)) return reply(req, http::status::ok, std::string(a->body, a->size), a->content_type);
        try {
            if (path == "/api/status") return json_reply(req, http::status::ok, status());
            if (path == "/api/live") return json_reply(req, http::status::ok, daemon.live_json());
            if (path == "/api/zones") return json_reply(req, http::status::ok, zones_json());
            if (path == "/api/history") {
                // ?span=1h|trial|campaign (default 1h); at most 720 points, thinned evenly.
                std::string span = "1h";
                if (query.rfind("span=", 0) == 0) span = query.substr(5);
                return json_reply(req, http::status::ok, history.to_json(span));
            }
            if (path == "/api/alarms") return json_reply(req, http::status::ok, daemon.alarms_json());
            if (path == "/api/notes") {
                if (query.rfind("campaign=", 0) != 0) return error(req, http::status::bad_request, "expected ?campaign=NAME");
                return json_reply(req, http::status::ok, daemon.notes_json(percent_decoded(query.substr(9))));
            }
            if (path == "/api/alarm-history") return json_reply(req, http::status::ok, daemon.alarm_history_json());
            if (path == "/api/results") {
                std::optional<std::string> name;
                if (query.rfind("campaign=", 0) == 0) name = query.substr(9);
                if (!name) name = daemon.last_campaign();
                if (!name) return error(req, http::status::not_found, "no campaign has run yet");
                return json_reply(req, http::status::ok, {{"campaign", *name}, {"results", daemon.results_json(*name)}});
            }
            if (path == "/metrics")
                return reply(req, http::status::ok, console::prometheus_text(status(), daemon.live_json()),
                             "text/plain; version=0.0.4; charset=utf-8");
        } catch (const UserError& e) {
            return error(req, http::status::not_found, e.what());
        }
        return error(req, http::status::not_found, fmt::format("no such page: {}", path));
    }

    // Nothing a request holds may leave the server thread as an exception: that would end the
    // daemon (std::terminate). A failure is this request's 500, named, and the log's line.
    http::response<http::string_body> handle_safely(const http::request<http::string_body>& req) {
        try {
            return handle(req);
        } catch (const std::exception& e) {
            spdlog::error("console: {} {}: {}", std::string(req.method_string()), printable(std::string(req.target())), printable(e.what()));
            return error(req, http::status::internal_server_error, fmt::format("internal error: {}", printable(e.what())));
        }
    }

    // --- sessions -----------------------------------------------------------------------
    // Every connection, HTTP or WebSocket. `last_progress` is when it last did something useful:
    // connected, finished a request, or took an update. When every place is taken, an HTTP
    // connection makes room for the newcomer, the one longest without progress first (a slow
    // header writer, an idle keep-alive); an established WebSocket (an operator's live view)
    // goes only when every place is one, again the longest without progress (one that never
    // reads). So a flood of connections cannot take the live view off the page.
    struct Client {
        WebClock::time_point last_progress = WebClock::now();
        virtual ~Client() = default;
        virtual void drop() = 0;
        virtual int keep_priority() const { return 0; }  // higher: evicted later
    };
    std::list<std::weak_ptr<Client>> client_list;
    std::uint64_t evicted = 0;

    void admit(const std::shared_ptr<Client>& c) {
        client_list.remove_if([](const std::weak_ptr<Client>& w) { return w.expired(); });
        client_list.push_back(c);
    }
    // Makes room by dropping a client: the lowest keep_priority, then the longest without
    // progress; false when there is none.
    bool evict_longest_idle() {
        client_list.remove_if([](const std::weak_ptr<Client>& w) { return w.expired(); });
        std::shared_ptr<Client> oldest;
        for (const auto& w : client_list) {
            auto c = w.lock();
            if (!c) continue;
            if (!oldest || c->keep_priority() < oldest->keep_priority() ||
                (c->keep_priority() == oldest->keep_priority() && c->last_progress < oldest->last_progress))
                oldest = c;
        }
        if (!oldest) return false;
        client_list.remove_if([&](const std::weak_ptr<Client>& w) { return w.lock() == oldest; });
        oldest->drop();
        ++evicted;
        return true;
    }

    struct WsSession : Client, std::enable_shared_from_this<WsSession> {
        WsSession(Impl& server, tcp::socket socket) : owner(server), ws(std::move(socket)) {}
        void drop() override {
            open = false;
            beast::error_code ignored;
            beast::get_lowest_layer(ws).socket().close(ignored);
        }
        ~WsSession() { --owner.clients; }
        int keep_priority() const override { return open ? 1 : 0; }
        Impl& owner;
        websocket::stream<beast::tcp_stream> ws;
        beast::flat_buffer incoming;
        std::deque<std::shared_ptr<const std::string>> outgoing;
        std::size_t outgoing_bytes = 0;
        bool open = false;

        void start(http::request<http::string_body> req) {
            beast::get_lowest_layer(ws).expires_never();
            auto timeouts = websocket::stream_base::timeout::suggested(beast::role_type::server);
            timeouts.idle_timeout = seconds(owner.o.idle_timeout_s);
            timeouts.keep_alive_pings = true;
            ws.set_option(timeouts);
            ws.read_message_max(kConsoleWsMaxMessageBytes);
            ws.async_accept(req, [self = shared_from_this()](beast::error_code ec) {
                if (ec) return;
                self->open = true;
                self->last_progress = WebClock::now();
                self->owner.admit(self);
                self->owner.sockets.push_back(self);
                self->send(std::make_shared<const std::string>(dump_json(self->owner.update_message())));
                self->read();
            });
        }
        void read() {
            ws.async_read(incoming, [self = shared_from_this()](beast::error_code ec, std::size_t) {
                if (ec) {
                    self->open = false;
                    return;
                }
                self->incoming.consume(self->incoming.size());
                self->read();
            });
        }
        void send(std::shared_ptr<const std::string> message) {
            if (!open) return;
            outgoing_bytes += message->size();
            outgoing.push_back(std::move(message));
            if (outgoing_bytes > owner.o.max_unsent_bytes) {  // the client stopped reading: let it go
                spdlog::info("console: a WebSocket client {} bytes behind; disconnected", outgoing_bytes);
                open = false;
                beast::get_lowest_layer(ws).close();
                return;
            }
            if (outgoing.size() == 1) write();
        }
        void write() {
            ws.text(true);
            ws.async_write(asio::buffer(*outgoing.front()), [self = shared_from_this()](beast::error_code ec, std::size_t) {
                if (ec) {
                    self->open = false;
                    return;
                }
                self->outgoing_bytes -= self->outgoing.front()->size();
                self->outgoing.pop_front();
                self->last_progress = WebClock::now();
                if (!self->outgoing.empty()) self->write();
            });
        }
    };

    struct HttpSession : Client, std::enable_shared_from_this<HttpSession> {
        HttpSession(Impl& server, tcp::socket socket) : owner(server), stream(std::move(socket)) {}
        void drop() override {
            beast::error_code ignored;
            stream.socket().shutdown(tcp::socket::shutdown_both, ignored);
            stream.socket().close(ignored);
        }
        ~HttpSession() {
            if (!upgraded) --owner.clients;
        }
        Impl& owner;
        beast::tcp_stream stream;
        beast::flat_buffer buffer;
        std::optional<http::request_parser<http::string_body>> parser;
        http::response<http::string_body> response;
        bool upgraded = false;

        void read() {
            parser.emplace();
            parser->header_limit(kConsoleHeaderLimitBytes);
            parser->body_limit(owner.api.max_message_bytes);
            stream.expires_after(seconds(owner.o.idle_timeout_s));
            http::async_read(stream, buffer, *parser, [self = shared_from_this()](beast::error_code ec, std::size_t) {
                self->on_read(ec);
            });
        }
        void on_read(beast::error_code ec) {
            if (ec) {
                if (ec == http::error::header_limit) {  // RFC 6585 5: say so, then close
                    http::request<http::string_body> req;
                    return respond(owner.error(req, http::status::request_header_fields_too_large,
                                               fmt::format("request headers over the limit of {} bytes", kConsoleHeaderLimitBytes)),
                                   true);
                }
                if (ec == http::error::body_limit) {
                    http::request<http::string_body> req;
                    return respond(owner.error(req, http::status::payload_too_large,
                                               fmt::format("request over the limit of {} bytes", owner.api.max_message_bytes)),
                                   true);
                }
                beast::error_code ignored;
                stream.socket().shutdown(tcp::socket::shutdown_both, ignored);
                return;
            }
            auto req = parser->release();
            if (websocket::is_upgrade(req)) {
                if (!owner.host_allowed(req) || !owner.origin_allowed(req))
                    return respond(owner.error(req, http::status::forbidden, "WebSocket from another site or host refused"), true);
                if (req.target() != "/ws") return respond(owner.error(req, http::status::not_found, "the WebSocket is at /ws"), true);
                upgraded = true;  // the count moves to the WebSocket session
                std::make_shared<WsSession>(owner, stream.release_socket())->start(std::move(req));
                return;
            }
            respond(owner.handle_safely(req), !req.keep_alive());
        }
        void respond(http::response<http::string_body> res, bool close_after) {
            response = std::move(res);
            if (close_after) response.keep_alive(false);
            http::async_write(stream, response, [self = shared_from_this(), close_after](beast::error_code ec, std::size_t) {
                if (ec || close_after || !self->response.keep_alive()) {
                    beast::error_code ignored;
                    self->stream.socket().shutdown(tcp::socket::shutdown_send, ignored);
                    return;
                }
                self->last_progress = WebClock::now();
                self->read();
            });
        }
    };

    void accept() {
        acceptor->async_accept([this](beast::error_code ec, tcp::socket socket) {
            if (ec == asio::error::operation_aborted) return;
            if (!ec) {
                // New connections from one address come at most at a rate (a burst allowed):
                // past it a newcomer is told 503 and closed, taking no one's place.
                if (!connection_allowed(socket)) return accept();
                // At most max_clients connections: a newcomer takes the place of another (HTTP
                // first, an established WebSocket last), closed at once (its descriptor freed).
                client_list.remove_if([](const std::weak_ptr<Client>& w) { return w.expired(); });
                if (client_list.size() >= o.max_clients && evict_longest_idle() && (evicted & (evicted - 1)) == 0)
                    spdlog::info("console: {} clients connected; one let go for a new one (an HTTP client first, a WebSocket last) "
                                 "({} so far)", o.max_clients, evicted);
                ++clients;
                auto session = std::make_shared<HttpSession>(*this, std::move(socket));
                admit(session);
                session->read();
                return accept();
            }
            // Out of descriptors or similar: pause instead of spinning.
            push_timer_retry_accept();
        });
    }
    // Per-address token buckets for new connections (server thread only).
    struct Bucket {
        double tokens = 0;
        WebClock::time_point refilled{};
    };
    std::map<std::string, Bucket> connection_buckets;
    std::uint64_t rate_limited = 0;
    bool connection_allowed(tcp::socket& socket) {
        beast::error_code ec;
        const auto remote = socket.remote_endpoint(ec);
        if (ec) return true;  // already gone: the session's first read says so
        const auto now = WebClock::now();
        if (connection_buckets.size() > 1024)  // forget addresses whose bucket has refilled
            std::erase_if(connection_buckets, [&](const auto& kv) {
                return kv.second.tokens + std::chrono::duration<double>(now - kv.second.refilled).count() *
                                              o.new_connections_per_s_per_ip >= o.new_connection_burst;
            });
        auto [it, fresh] = connection_buckets.try_emplace(remote.address().to_string(), Bucket{o.new_connection_burst, now});
        Bucket& b = it->second;
        if (!fresh) {
            b.tokens = std::min(o.new_connection_burst,
                                b.tokens + std::chrono::duration<double>(now - b.refilled).count() * o.new_connections_per_s_per_ip);
            b.refilled = now;
        }
        if (b.tokens >= 1.0) {
            b.tokens -= 1.0;
            return true;
        }
        ++rate_limited;
        if ((rate_limited & (rate_limited - 1)) == 0)
            spdlog::info("console: new connections from {} over {} per second; refused with 503 ({} so far)", it->first,
                         o.new_connections_per_s_per_ip, rate_limited);
        static const std::string busy =
            "HTTP/1.1 503 Service Unavailable\r\nRetry-After: 1\r\nContent-Length: 0\r\nConnection: close\r\n\r\n";
        const int fd = socket.native_handle();
        [[maybe_unused]] const auto n = ::send(fd, busy.data(), busy.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
        // What it sent already is read and dropped: a close with bytes unread would reset the
        // connection, and the 503 with it.
        std::array<char, 4096> scratch{};
        for (int i = 0; i < 4 && ::recv(fd, scratch.data(), scratch.size(), MSG_DONTWAIT) > 0; ++i) {
        }
        ::shutdown(fd, SHUT_WR);
        socket.close(ec);
        return false;
    }

    std::optional<asio::steady_timer> accept_retry;
    void push_timer_retry_accept() {
        accept_retry->expires_after(std::chrono::milliseconds(100));
        accept_retry->async_wait([this](beast::error_code ec) {
            if (!ec) accept();
        });
    }

    // Updates go out when a sample arrives (a burst coalesced over 20 ms: the issue asks under 50 ms from sample to screen) and at least once a second.
    void broadcast() {
        last_push = WebClock::now();
        // The oldest sample in this update reached the daemon then: the page (and bench_console)
        // measures sample-to-screen latency from it.
        const double oldest_sample_utc_ms = sample_pending.exchange(false) ? pending_since_utc_ms.load() : 0.0;
        sockets.remove_if([](const std::weak_ptr<WsSession>& w) {
            auto s = w.lock();
            return !s || !s->open;
        });
        if (sockets.empty()) return;
        auto update = update_message();
        update["oldest_new_sample_utc_ms"] = oldest_sample_utc_ms > 0 ? nlohmann::json(oldest_sample_utc_ms) : nlohmann::json(nullptr);
        const auto message = std::make_shared<const std::string>(dump_json(update));
        for (auto& w : sockets)
            if (auto s = w.lock()) s->send(message);
    }
    void on_sample_posted() {
        if (push_scheduled) return;
        const auto due = last_push + std::chrono::milliseconds(20);
        if (WebClock::now() >= due) return broadcast();
        push_scheduled = true;
        push_timer->expires_at(due);
        push_timer->async_wait([this](beast::error_code ec) {
            push_scheduled = false;
            if (!ec) broadcast();
        });
    }
    void tick() {
        if (WebClock::now() - last_push >= std::chrono::milliseconds(900)) broadcast();
        else record_history(daemon.live_json(), daemon.status_json());
        tick_timer->expires_after(std::chrono::seconds(1));
        tick_timer->async_wait([this](beast::error_code ec) {
            if (!ec) tick();
        });
    }
};

WebServer::WebServer(LabDaemon& daemon, ControlOptions api, WebOptions options)
    : impl_(std::make_unique<Impl>(daemon, std::move(api), std::move(options))) {}
WebServer::~WebServer() { stop(); }
int WebServer::port() const { return impl_->bound_port; }
std::string WebServer::url() const { return fmt::format("http://{}/", impl_->authority(impl_->bound_port)); }

std::string WebServer::answer_raw(const std::string& request_bytes) {
    Impl& s = *impl_;
    if (s.allowed_hosts.empty()) s.allow_hosts_for(s.o.port);
    http::request_parser<http::string_body> parser;
    parser.header_limit(kConsoleHeaderLimitBytes);
    parser.body_limit(s.api.max_message_bytes);
    parser.eager(true);
    beast::error_code ec;
    std::size_t used = 0;
    while (used < request_bytes.size() && !parser.is_done()) {
        const std::size_t n = parser.put(asio::buffer(request_bytes.data() + used, request_bytes.size() - used), ec);
        if (ec == http::error::need_more) break;
        if (ec == http::error::header_limit) {  // the server says 431, then closes
            std::ostringstream out;
            out << s.error(http::request<http::string_body>{}, http::status::request_header_fields_too_large,
                           fmt::format("request headers over the limit of {} bytes", kConsoleHeaderLimitBytes));
            return out.str();
        }
        if (ec) return {};
        used += n;
        if (n == 0) break;
    }
    if (!parser.is_done()) {
        if (!parser.got_some()) return {};  // nothing arrived: the server waits, then closes
        parser.put_eof(ec);
        if (ec || !parser.is_done()) return {};
    }
    auto req = parser.release();
    if (websocket::is_upgrade(req)) return {};  // the WebSocket has its own path (fuzz_console's second half)
    const auto res = s.handle_safely(req);
    std::ostringstream out;
    out << res;
    return out.str();
}
bool WebServer::shutdown_requested() const { return impl_->shutdown.load(); }

void WebServer::start() {
    Impl& s = *impl_;
    if (!is_loopback(s.o.host)) throw UserError(fmt::format("the console listens on a loopback address only, not {}", s.o.host));
    const auto address = asio::ip::make_address(s.o.host);
    const tcp::endpoint endpoint(address, static_cast<std::uint16_t>(s.o.port));
    s.acceptor.emplace(*s.io);
    beast::error_code ec;
    s.acceptor->open(endpoint.protocol(), ec);
    if (!ec) s.acceptor->set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) s.acceptor->bind(endpoint, ec);
    if (!ec) s.acceptor->listen(asio::socket_base::max_listen_connections, ec);
    if (ec) throw UserError(fmt::format("console: cannot listen on {}:{}: {}", s.o.host, s.o.port, ec.message()));
    s.bound_port = s.acceptor->local_endpoint().port();
    s.allow_hosts_for(s.bound_port);
    s.push_timer.emplace(*s.io);
    s.tick_timer.emplace(*s.io);
    s.accept_retry.emplace(*s.io);
    s.daemon.set_sample_listener([&s] {
        if (!s.sample_pending.exchange(true)) {
            s.pending_since_utc_ms = utc_ms();
            asio::post(*s.io, [&s] { s.on_sample_posted(); });
        }
    });
    s.accept();
    s.tick();
    s.thread = std::thread([&s] { run_guarded("console", [&s] { s.io->run(); }); });
    // The charts' spans reach back before this start: the database's last history_s, read on a
    // thread of its own (seconds for a day of trials), merged on the server thread.
    s.seeder = std::thread([&s] {
        std::vector<console::ChamberHistory::Point> points;
        std::map<std::string, std::int64_t> starts;
        try {
            const auto now_ns = s.daemon.lab_utc_ns();
            points = history_from_database(s.daemon.database_path(), now_ns - static_cast<std::int64_t>(s.o.history_s * 1e9), 5.0, starts);
        } catch (const std::exception& e) {
            spdlog::warn("console: the chamber history before this start could not be read from the database: {}", e.what());
        }
        asio::post(*s.io, [&s, points = std::move(points), starts = std::move(starts)]() mutable {
            s.history.seed(std::move(points), s.daemon.virtual_time_s(), s.daemon.lab_utc_ns() / 1'000'000, std::move(starts));
            std::lock_guard lk(s.seed_lock);
            s.seeded = true;
            s.seed_done.notify_all();
        });
    });
}

bool WebServer::wait_history_seeded(std::chrono::milliseconds within) {
    std::unique_lock lk(impl_->seed_lock);
    return impl_->seed_done.wait_for(lk, within, [this] { return impl_->seeded; });
}

void WebServer::stop() {
    Impl& s = *impl_;
    s.daemon.set_sample_listener({});
    if (s.seeder.joinable()) s.seeder.join();  // its merge runs on the server thread, or not at all once stopped
    if (!s.io) return;
    if (s.thread.joinable()) {
        s.io->stop();
        s.thread.join();
    }
    s.acceptor.reset();
    s.push_timer.reset();
    s.tick_timer.reset();
    s.accept_retry.reset();
    s.sockets.clear();
    s.io.reset();
}

}  // namespace manikind
