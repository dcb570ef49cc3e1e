#pragma once
// Notifications away from the screen (issue 35; docs/daemon.md, "Notifications"): what happens in
// the lab (a safety trip, an alarm, a trial or campaign ending, a trial reaching steady state)
// sent by webhook (JSON for ntfy and the like, Slack's or Matrix's message shape) and by e-mail
// (SMTP), with libcurl, on a thread of its own. post() never waits for the network: acquisition
// is never held by a slow or absent receiver. Each destination is rate-limited (what comes
// within the interval is sent together at its end), retried with backoff, and counted.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

namespace manikind {

struct Notice {
    std::string kind;      // safety, alarm_error, alarm_warn, trial_end, campaign_end, steady
    std::string severity;  // info, warn, error
    std::string title;     // one line
    std::string body;      // details
    std::int64_t utc_ns = 0;
};

// The kinds a rule may name (config [notifications] events).
const std::set<std::string>& notice_kinds();

struct NotifierOptions {
    std::string lab_name = "manikind";
    std::set<std::string> events;        // kinds sent; empty: nothing
    std::string webhook_url;             // http:// or https://; empty: no webhook
    std::string webhook_format = "json"; // json, slack, matrix
    std::string smtp_url;                // smtp:// or smtps://host:port; empty: no e-mail
    std::string mail_from;
    std::vector<std::string> mail_to;
    double min_interval_s = 60.0;        // per destination
    int retries = 4;                     // after the first try, backoff 1, 2, 4 ... s
    double timeout_s = 10.0;             // per try
    std::size_t max_queue = 1000;        // notices waiting beyond this: the oldest dropped, counted
};

class Notifier {
public:
    explicit Notifier(NotifierOptions options);
    ~Notifier();  // stops; what is still waiting is tried once more for at most `timeout_s`
    Notifier(const Notifier&) = delete;
    Notifier& operator=(const Notifier&) = delete;

    bool wants(const std::string& kind) const { return o_.events.count(kind) > 0; }
    // O(1) and never blocks on the network. Notices of kinds not wanted are ignored.
    void post(Notice notice);
    // Per destination: sent, failed (after every retry), dropped (queue full), waiting, last error.
    nlohmann::json status_json() const;
    // Blocks until nothing waits (or `within` passes): for tests and an orderly exit.
    bool drain(std::chrono::milliseconds within);

    // The messages as they go out (exposed for tests).
    static std::string webhook_body(const std::string& format, const std::string& lab, const std::vector<Notice>& notices);
    static std::string mail_text(const std::string& from, const std::vector<std::string>& to, const std::string& lab,
                                 const std::vector<Notice>& notices, std::int64_t date_utc_ns);

private:
    struct Destination {
        std::string name;  // "webhook", "email"
        std::deque<Notice> waiting;
        std::chrono::steady_clock::time_point next_allowed{};
        std::uint64_t sent = 0, failed = 0, dropped = 0, messages = 0;
        std::string last_error;
    };
    void run();
    std::string send(Destination& d, const std::vector<Notice>& batch);  // "" when delivered

    NotifierOptions o_;
    mutable std::mutex lock_;
    std::condition_variable wake_;
    std::vector<Destination> dest_;
    bool stop_ = false;
    bool busy_ = false;
    std::thread worker_;
};

}  // namespace manikind
