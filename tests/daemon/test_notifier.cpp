// Notifications (daemon/notifier.hpp, issue 35 item 3) against receivers not written here:
// Python's HTTP server for the webhook and aiosmtpd for e-mail (tests/daemon/notify_peers.py).
// Delivery, retries after a refusal, the rate limit's summary, a dead receiver that never holds
// the caller, and the daemon's own notices (an alarm once per episode, the campaign's end).
#include <catch2/catch.hpp>

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "daemon/notifier.hpp"
#include "daemon_fixture.hpp"

using manikind::Notice;
using manikind::Notifier;
using manikind::NotifierOptions;

namespace {

// A receiver started by the test: its port from its first line, then one JSON line per delivery.
class Peer {
public:
    Peer(const std::string& mode, int count, int fail_first = 0) {
        const std::string cmd = fmt::format("/usr/bin/python3 {}/daemon/notify_peers.py {} {} {}", MANIKIND_TESTS_DIR, mode, count,
                                            fail_first);
        pipe_ = popen(cmd.c_str(), "r");
        if (!pipe_) return;
        const std::string first = line();
        if (first.rfind("port ", 0) == 0) port_ = std::stoi(first.substr(5));
        else skip_ = first;
    }
    ~Peer() {
        if (pipe_) pclose(pipe_);  // the peer exits after its count (or its own 120 s)
    }
    int port() const { return port_; }
    const std::string& skip_reason() const { return skip_; }
    // The next delivery (blocks until the peer prints it; the peer's own limit bounds the wait).
    nlohmann::json next() {
        const std::string l = line();
        return l.empty() ? nlohmann::json() : nlohmann::json::parse(l);
    }

private:
    std::string line() {
        std::string out;
        char buf[4096];
        while (pipe_ && std::fgets(buf, sizeof buf, pipe_)) {
            out += buf;
            if (!out.empty() && out.back() == '\n') {
                out.pop_back();
                return out;
            }
        }
        return out;
    }
    FILE* pipe_ = nullptr;
    int port_ = 0;
    std::string skip_;
};

Notice notice(const std::string& kind, const std::string& title, const std::string& body = "details") {
    return {kind, kind == "safety" || kind == "alarm_error" ? "error" : "info", title, body, 1'780'000'000'000'000'000};
}

}  // namespace

TEST_CASE("notifier: a webhook receives the notices as JSON, after the receiver refused twice", "[daemon][notify]") {
    Peer peer("http", 1, 2);
    REQUIRE(peer.port() > 0);
    NotifierOptions o;
    o.lab_name = "chamber-3";
    o.events = {"safety", "campaign_end"};
    o.webhook_url = fmt::format("http://127.0.0.1:{}/hook", peer.port());
    o.min_interval_s = 0;
    o.retries = 3;
    Notifier n(o);
    n.post(notice("steady", "not wanted: not in events"));
    n.post(notice("safety", "SAFETY STOP: heating stopped", "watchdog: manikin silent for more than 5 s"));
    const auto got = peer.next();
    REQUIRE(got.is_object());
    CHECK(got["path"] == "/hook");
    CHECK(got["content_type"] == "application/json");
    CHECK(got["title"] == "[chamber-3] SAFETY STOP: heating stopped");
    CHECK(got["body"]["lab"] == "chamber-3");
    CHECK(got["body"]["severity"] == "error");
    REQUIRE(got["body"]["notices"].size() == 1);  // the steady notice was not wanted
    CHECK(got["body"]["notices"][0]["body"] == "watchdog: manikin silent for more than 5 s");
    REQUIRE(n.drain(std::chrono::seconds(30)));
    const auto st = n.status_json();
    CHECK(st["webhook"]["notices_sent"] == 1);
    CHECK(st["webhook"]["notices_failed"] == 0);
    CHECK(st["webhook"]["last_error"] == "");
}

TEST_CASE("notifier: e-mail through a real SMTP server, headers that cannot be smuggled into", "[daemon][notify]") {
    Peer peer("smtp", 1);
    if (!peer.skip_reason().empty()) {
        WARN(peer.skip_reason());
        return;
    }
    REQUIRE(peer.port() > 0);
    NotifierOptions o;
    o.lab_name = "chamber-3";
    o.events = {"campaign_end"};
    o.smtp_url = fmt::format("smtp://127.0.0.1:{}", peer.port());
    o.mail_from = "manikind@lab.example";
    o.mail_to = {"ana@lab.example", "bo@lab.example"};
    o.min_interval_s = 0;
    Notifier n(o);
    n.post(notice("campaign_end", "campaign 'astm-0425' done\r\nBcc: everyone@example.com", "case 1 replicate 1: done\ncase 1 replicate 2: done"));
    const auto got = peer.next();
    REQUIRE(got.is_object());
    CHECK(got["from"] == "manikind@lab.example");
    CHECK(got["to"] == nlohmann::json::array({"ana@lab.example", "bo@lab.example"}));
    const std::string data = got["data"];
    CHECK(data.find("Subject: [chamber-3] campaign 'astm-0425' done") != std::string::npos);
    CHECK(data.find("\nBcc:") == std::string::npos);  // the CR LF in the title stayed inside the subject
    CHECK(data.find("case 1 replicate 2: done") != std::string::npos);
    REQUIRE(n.drain(std::chrono::seconds(30)));
    CHECK(n.status_json()["email"]["notices_sent"] == 1);
}

TEST_CASE("notifier: within the interval notices wait and go together, and a dead receiver never holds the caller",
          "[daemon][notify][proof]") {
    SECTION("rate limit: the first at once, the next three as one message") {
        Peer peer("http", 2);
        REQUIRE(peer.port() > 0);
        NotifierOptions o;
        o.events = {"alarm_warn"};
        o.webhook_url = fmt::format("http://127.0.0.1:{}/", peer.port());
        o.min_interval_s = 1.0;
        Notifier n(o);
        n.post(notice("alarm_warn", "first"));
        const auto one = peer.next();
        REQUIRE(one.is_object());
        CHECK(one["body"]["notices"].size() == 1);
        for (const char* t : {"second", "third", "fourth"}) n.post(notice("alarm_warn", t));
        const auto together = peer.next();
        REQUIRE(together.is_object());
        CHECK(together["body"]["notices"].size() == 3);
        CHECK(together["body"]["title"].get<std::string>().find("3 notices: second") != std::string::npos);
        REQUIRE(n.drain(std::chrono::seconds(30)));
        CHECK(n.status_json()["webhook"]["messages"] == 2);
    }
    SECTION("nobody listening: post returns at once, the failure is counted with its reason") {
        NotifierOptions o;
        o.events = {"alarm_error"};
        o.webhook_url = "http://127.0.0.1:9/";  // discard port: nothing listens (connection refused)
        o.min_interval_s = 0;
        o.retries = 1;
        o.max_queue = 5;
        Notifier n(o);
        // A thousand posts while the worker is busy failing: the queue stays bounded, nothing blocks.
        for (int i = 0; i < 1000; ++i) n.post(notice("alarm_error", fmt::format("alarm {}", i)));
        REQUIRE(n.drain(std::chrono::seconds(60)));
        const auto st = n.status_json()["webhook"];
        CHECK(st["notices_failed"].get<int>() + st["notices_dropped"].get<int>() == 1000);
        CHECK(st["notices_dropped"].get<int>() > 0);
        CHECK(st["last_error"].get<std::string>().find("Couldn't connect") != std::string::npos);
    }
}

TEST_CASE("notifier: message shapes for ntfy-style JSON, Slack and Matrix", "[daemon][notify]") {
    const std::vector<Notice> two{notice("trial_end", "trial 4 done"), notice("alarm_error", "alarm: gap (chamber)", "chamber lost")};
    const auto json = nlohmann::json::parse(Notifier::webhook_body("json", "lab", two));
    CHECK(json["severity"] == "error");
    CHECK(json["notices"].size() == 2);
    CHECK(nlohmann::json::parse(Notifier::webhook_body("slack", "lab", two))["text"].get<std::string>().find("[lab] alarm: gap (chamber): chamber lost") !=
          std::string::npos);
    const auto matrix = nlohmann::json::parse(Notifier::webhook_body("matrix", "lab", two));
    CHECK(matrix["msgtype"] == "m.text");
    CHECK(matrix["body"].get<std::string>().find("trial 4 done") != std::string::npos);
    // Not UTF-8 from a device's error text: replaced, never a throw.
    const std::vector<Notice> bad{notice("alarm_warn", "alarm", std::string("bytes \xff\xfe here"))};
    CHECK_NOTHROW(nlohmann::json::parse(Notifier::webhook_body("json", "lab", bad)));
}

TEST_CASE("notifier: Slack and Matrix markup in a notice is escaped and pings nobody", "[daemon][notify]") {
    // A campaign name or alarm text from outside, written to ping a whole channel or room.
    const std::vector<Notice> hostile{notice("campaign_end", "campaign <!channel> & <https://x.example|click> done",
                                             "@room look <@U123>")};
    const auto slack = nlohmann::json::parse(Notifier::webhook_body("slack", "lab", hostile))["text"].get<std::string>();
    CHECK(slack.find('<') == std::string::npos);
    CHECK(slack.find('>') == std::string::npos);
    CHECK(slack.find("&lt;!channel&gt; &amp; &lt;https://x.example|click&gt;") != std::string::npos);
    const auto matrix = nlohmann::json::parse(Notifier::webhook_body("matrix", "lab", hostile));
    CHECK(matrix["body"].get<std::string>().find("@room") == std::string::npos);
    CHECK(matrix["body"].get<std::string>().find("look") != std::string::npos);
    REQUIRE(matrix.contains("m.mentions"));
    CHECK(matrix["m.mentions"].empty());
}

TEST_CASE("the daemon's notices: an alarm once per episode, a trial's and the campaign's end", "[daemon][notify]") {
    manikind::test::DaemonFixture f([](manikind::config::Config& c) { c.simulation.faults = {"windsonic:silent@5-20", "windsonic:silent@40-55"}; });
    std::vector<std::string> kinds, titles;
    f.daemon().set_notice_listener([&](const std::string& kind, const std::string&, const std::string& title, const std::string&, std::int64_t) {
        kinds.push_back(kind);
        titles.push_back(title);
    });
    REQUIRE(f.daemon().start_campaign(manikind::test::quick_plan("notify", 35.0)).empty());
    for (int i = 0; i < 4 * 3600 && f.daemon().status_json()["campaign"].is_string(); ++i) f.daemon().step_virtual(1.0);
    auto count = [&](const std::string& kind) { return std::count(kinds.begin(), kinds.end(), kind); };
    // The WindSonic dropped out twice: one alarm line, so one notice (its second episode re-opens
    // the same unacknowledged alarm).
    CHECK(count("alarm_warn") >= 1);
    CHECK(std::count(titles.begin(), titles.end(), "alarm: gap (windsonic)") == 1);
    CHECK(count("trial_end") == 1);
    CHECK(count("campaign_end") == 1);
    CHECK(count("steady") == 1);
    CHECK(count("safety") == 0);
}
