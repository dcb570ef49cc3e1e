#include "daemon/notifier.hpp"

#include <curl/curl.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <ctime>

#include "base/guarded.hpp"
#include "base/lazy_library.hpp"
#include "base/user_error.hpp"
#include "base/text.hpp"

namespace manikind {

namespace {

using NotifierClock = std::chrono::steady_clock;

// libcurl, loaded when notifications are configured, not at every program's start
// (base/lazy_library.hpp). Each member is the curl_ function of the same name without "curl_".
struct Curl {
    decltype(&::curl_easy_cleanup) easy_cleanup = nullptr;
    decltype(&::curl_easy_getinfo) easy_getinfo = nullptr;
    decltype(&::curl_easy_init) easy_init = nullptr;
    decltype(&::curl_easy_perform) easy_perform = nullptr;
    decltype(&::curl_easy_setopt) easy_setopt = nullptr;
    decltype(&::curl_easy_strerror) easy_strerror = nullptr;
    decltype(&::curl_global_init) global_init = nullptr;
    decltype(&::curl_slist_append) slist_append = nullptr;
    decltype(&::curl_slist_free_all) slist_free_all = nullptr;
};

// UserError (code missing_library) when libcurl cannot be loaded. curl_global_init runs here, once,
// before any thread uses libcurl (it is not thread-safe itself).
const Curl& curl() {
    static LazyLibrary library("libmanikind-curl.so", "libcurl (for notifications)");
    return library.table<Curl>([](LazyLibrary& l, Curl& a) {
        MANIKIND_BIND(l, a, easy_cleanup, curl_easy_cleanup);
        MANIKIND_BIND(l, a, easy_getinfo, curl_easy_getinfo);
        MANIKIND_BIND(l, a, easy_init, curl_easy_init);
        MANIKIND_BIND(l, a, easy_perform, curl_easy_perform);
        MANIKIND_BIND(l, a, easy_setopt, curl_easy_setopt);
        MANIKIND_BIND(l, a, easy_strerror, curl_easy_strerror);
        MANIKIND_BIND(l, a, global_init, curl_global_init);
        MANIKIND_BIND(l, a, slist_append, curl_slist_append);
        MANIKIND_BIND(l, a, slist_free_all, curl_slist_free_all);
        if (a.global_init(CURL_GLOBAL_DEFAULT) != CURLE_OK)
            throw UserError("libcurl did not initialise (curl_global_init failed)", "missing_library");
    });
}

struct Easy {
    CURL* h = curl().easy_init();
    curl_slist* list = nullptr;
    ~Easy() {
        if (list) curl().slist_free_all(list);
        if (h) curl().easy_cleanup(h);
    }
};

std::size_t discard(char*, std::size_t size, std::size_t n, void*) { return size * n; }

struct Upload {
    std::string text;
    std::size_t at = 0;
};
std::size_t read_upload(char* out, std::size_t size, std::size_t n, void* user) {
    auto* u = static_cast<Upload*>(user);
    const std::size_t len = std::min(size * n, u->text.size() - u->at);
    std::memcpy(out, u->text.data() + u->at, len);
    u->at += len;
    return len;
}

std::string rfc5322_date(std::int64_t utc_ns) {
    const std::time_t t = static_cast<std::time_t>(utc_ns / 1'000'000'000);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[64];
    std::strftime(buf, sizeof buf, "%a, %d %b %Y %H:%M:%S +0000", &tm);
    return buf;
}

// A header value on one line, printable: no CR/LF can start a header of its own.
std::string header_safe(std::string_view v) {
    std::string out = printable(v, 200);
    std::replace(out.begin(), out.end(), '\r', ' ');
    std::replace(out.begin(), out.end(), '\n', ' ');
    return out;
}

std::string summary(const std::vector<Notice>& notices) {
    if (notices.size() == 1) return notices.front().title;
    return fmt::format("{} notices: {} (and {} more)", notices.size(), notices.front().title, notices.size() - 1);
}

}  // namespace

const std::set<std::string>& notice_kinds() {
    static const std::set<std::string> k{"safety", "alarm_error", "alarm_warn", "trial_end", "campaign_end", "steady"};
    return k;
}

std::string Notifier::webhook_body(const std::string& format, const std::string& lab, const std::vector<Notice>& notices) {
    std::string text;
    for (const auto& n : notices) text += (text.empty() ? "" : "\n") + fmt::format("[{}] {}: {}", lab, n.title, n.body);
    // Each target's markup is escaped: the text comes partly from outside (campaign names, alarm
    // messages, note authors). Slack reads &, < and > as control characters (`<!channel>` pings the
    // whole channel, `<url|text>` makes a link): they go as &amp; &lt; &gt;, as Slack's
    // "Formatting text" asks. Matrix: an empty m.mentions (intentional mentions, spec v1.7) so no
    // word in the body pings anyone, and "@room" broken by a word joiner for older clients.
    if (format == "slack") {
        std::string escaped;
        for (const char c : text) {
            if (c == '&') escaped += "&amp;";
            else if (c == '<') escaped += "&lt;";
            else if (c == '>') escaped += "&gt;";
            else escaped += c;
        }
        return dump_json({{"text", escaped}});
    }
    if (format == "matrix") {
        std::string body = text;
        for (std::size_t at = body.find("@room"); at != std::string::npos; at = body.find("@room", at + 1))
            body.insert(at + 1, "\u2060");
        return dump_json({{"msgtype", "m.text"}, {"body", body}, {"m.mentions", nlohmann::json::object()}});
    }
    // json (ntfy's JSON publishing, generic receivers): the notices themselves, and a title.
    nlohmann::json list = nlohmann::json::array();
    std::string worst = "info";
    for (const auto& n : notices) {
        list.push_back({{"kind", n.kind}, {"severity", n.severity}, {"title", n.title}, {"body", n.body}, {"utc_ns", n.utc_ns}});
        if (n.severity == "error" || (n.severity == "warn" && worst == "info")) worst = n.severity;
    }
    return dump_json({{"lab", lab}, {"title", fmt::format("[{}] {}", lab, summary(notices))}, {"message", text},
                      {"severity", worst}, {"notices", list}});
}

std::string Notifier::mail_text(const std::string& from, const std::vector<std::string>& to, const std::string& lab,
                                const std::vector<Notice>& notices, std::int64_t date_utc_ns) {
    std::string recipients;
    for (const auto& r : to) recipients += (recipients.empty() ? "" : ", ") + header_safe(r);
    std::string m = fmt::format("Date: {}\r\nFrom: {}\r\nTo: {}\r\nSubject: [{}] {}\r\nContent-Type: text/plain; charset=utf-8\r\n"
                                "Auto-Submitted: auto-generated\r\n\r\n",
                                rfc5322_date(date_utc_ns), header_safe(from), recipients, header_safe(lab), header_safe(summary(notices)));
    for (const auto& n : notices) {
        std::string body = n.body;
        // SMTP's transparency (RFC 5321 4.5.2) is libcurl's; bare LFs become CRLF here.
        std::string crlf;
        for (char c : body) {
            if (c == '\n') crlf += "\r\n";
            else if (c != '\r') crlf += c;
        }
        m += fmt::format("{} ({})\r\n{}\r\n\r\n", header_safe(n.title), n.severity, crlf);
    }
    return m;
}

Notifier::Notifier(NotifierOptions options) : o_(std::move(options)) {
    if (!o_.webhook_url.empty()) dest_.push_back({"webhook", {}, {}, 0, 0, 0, 0, {}});
    if (!o_.smtp_url.empty() && !o_.mail_to.empty()) dest_.push_back({"email", {}, {}, 0, 0, 0, 0, {}});
    if (!dest_.empty()) (void)curl();  // loaded now: a daemon without libcurl says so at start, not at its first notice
    worker_ = std::thread([this] { run_guarded("notifier", [this] { run(); }); });
}

Notifier::~Notifier() {
    {
        std::lock_guard lk(lock_);
        stop_ = true;
    }
    wake_.notify_all();
    if (worker_.joinable()) worker_.join();
}

void Notifier::post(Notice notice) {
    if (!wants(notice.kind)) return;
    {
        std::lock_guard lk(lock_);
        for (auto& d : dest_) {
            if (d.waiting.size() >= o_.max_queue) {
                d.waiting.pop_front();
                ++d.dropped;
            }
            d.waiting.push_back(notice);
        }
    }
    wake_.notify_all();
}

nlohmann::json Notifier::status_json() const {
    std::lock_guard lk(lock_);
    nlohmann::json out = nlohmann::json::object();
    for (const auto& d : dest_)
        out[d.name] = {{"messages", d.messages}, {"notices_sent", d.sent}, {"notices_failed", d.failed},
                       {"notices_dropped", d.dropped}, {"waiting", d.waiting.size()}, {"last_error", d.last_error}};
    return out;
}

bool Notifier::drain(std::chrono::milliseconds within) {
    const auto until = NotifierClock::now() + within;
    std::unique_lock lk(lock_);
    for (;;) {
        const bool empty = std::all_of(dest_.begin(), dest_.end(), [](const Destination& d) { return d.waiting.empty(); });
        if (empty && !busy_) return true;
        if (NotifierClock::now() >= until) return false;
        lk.unlock();
        wake_.notify_all();
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        lk.lock();
    }
}

void Notifier::run() {
    std::unique_lock lk(lock_);
    for (;;) {
        // The next destination with something to send whose interval has passed.
        const auto now = NotifierClock::now();
        Destination* ready = nullptr;
        auto next_wake = now + std::chrono::hours(1);
        for (auto& d : dest_) {
            if (d.waiting.empty()) continue;
            if (d.next_allowed <= now || stop_) {
                ready = &d;
                break;
            }
            next_wake = std::min(next_wake, d.next_allowed);
        }
        if (!ready) {
            if (stop_) return;
            wake_.wait_until(lk, next_wake);
            continue;
        }
        // Everything waiting for it goes as one message (the rate limit's summary).
        std::vector<Notice> batch(ready->waiting.begin(), ready->waiting.end());
        ready->waiting.clear();
        busy_ = true;
        const bool stopping = stop_;
        lk.unlock();
        std::string error;
        for (int attempt = 0; attempt <= (stopping ? 0 : o_.retries); ++attempt) {
            error = send(*ready, batch);
            if (error.empty()) break;
            spdlog::warn("notification by {} failed (try {} of {}): {}", ready->name, attempt + 1, o_.retries + 1, error);
            // Backoff 1, 2, 4 ... s, cut short by a stop.
            std::unique_lock wait_lk(lock_);
            if (wake_.wait_for(wait_lk, std::chrono::seconds(1LL << std::min(attempt, 6)), [this] { return stop_; })) break;
        }
        lk.lock();
        busy_ = false;
        ++ready->messages;
        if (error.empty()) {
            ready->sent += batch.size();
        } else {
            ready->failed += batch.size();
            ready->last_error = error;
        }
        ready->next_allowed = NotifierClock::now() + std::chrono::milliseconds(static_cast<long long>(o_.min_interval_s * 1000));
    }
}

std::string Notifier::send(Destination& d, const std::vector<Notice>& batch) {
    Easy e;
    if (!e.h) return "libcurl could not start a transfer";
    char err[CURL_ERROR_SIZE] = {0};
    curl().easy_setopt(e.h, CURLOPT_ERRORBUFFER, err);
    curl().easy_setopt(e.h, CURLOPT_NOSIGNAL, 1L);
    curl().easy_setopt(e.h, CURLOPT_TIMEOUT_MS, static_cast<long>(o_.timeout_s * 1000));
    curl().easy_setopt(e.h, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(std::min(o_.timeout_s, 5.0) * 1000));
    Upload up;
    std::int64_t date_ns = batch.empty() ? 0 : batch.back().utc_ns;
    if (d.name == "webhook") {
        up.text = webhook_body(o_.webhook_format, o_.lab_name, batch);
        curl().easy_setopt(e.h, CURLOPT_URL, o_.webhook_url.c_str());
        // Only the web's own schemes: a URL cannot turn the daemon into a file or gopher client.
        curl().easy_setopt(e.h, CURLOPT_PROTOCOLS_STR, "http,https");
        curl().easy_setopt(e.h, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
        e.list = curl().slist_append(e.list, "Content-Type: application/json");
        if (!batch.empty()) e.list = curl().slist_append(e.list, fmt::format("Title: [{}] {}", header_safe(o_.lab_name), header_safe(summary(batch))).c_str());
        curl().easy_setopt(e.h, CURLOPT_HTTPHEADER, e.list);
        curl().easy_setopt(e.h, CURLOPT_POSTFIELDS, up.text.c_str());
        curl().easy_setopt(e.h, CURLOPT_POSTFIELDSIZE, static_cast<long>(up.text.size()));
        curl().easy_setopt(e.h, CURLOPT_WRITEFUNCTION, discard);
    } else {
        up.text = mail_text(o_.mail_from, o_.mail_to, o_.lab_name, batch, date_ns);
        curl().easy_setopt(e.h, CURLOPT_URL, o_.smtp_url.c_str());
        curl().easy_setopt(e.h, CURLOPT_PROTOCOLS_STR, "smtp,smtps");
        curl().easy_setopt(e.h, CURLOPT_MAIL_FROM, ("<" + o_.mail_from + ">").c_str());
        for (const auto& r : o_.mail_to) e.list = curl().slist_append(e.list, ("<" + r + ">").c_str());
        curl().easy_setopt(e.h, CURLOPT_MAIL_RCPT, e.list);
        curl().easy_setopt(e.h, CURLOPT_READFUNCTION, read_upload);
        curl().easy_setopt(e.h, CURLOPT_READDATA, &up);
        curl().easy_setopt(e.h, CURLOPT_UPLOAD, 1L);
    }
    const CURLcode rc = curl().easy_perform(e.h);
    if (rc != CURLE_OK) return fmt::format("{}: {}", curl().easy_strerror(rc), err[0] ? err : "");
    if (d.name == "webhook") {
        long status = 0;
        curl().easy_getinfo(e.h, CURLINFO_RESPONSE_CODE, &status);
        if (status < 200 || status >= 300) return fmt::format("the receiver answered HTTP {}", status);
    }
    return {};
}

}  // namespace manikind
