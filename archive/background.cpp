#include "archive/background.hpp"
#include "base/guarded.hpp"

#include <algorithm>
#include <exception>

#include <fmt/core.h>

#include "archive/pg.hpp"
#include "base/user_error.hpp"

namespace manikind::archive {
namespace {

// Thrown from the chunk hook to end a pass early when the daemon stops.
struct StopRequested {};

std::int64_t utc_now_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

}  // namespace

BackgroundForwarder::BackgroundForwarder(ForwardingOptions options, ForwardingNotice notice)
    : o_(std::move(options)), notice_(std::move(notice)) {
    PgConnection::check_conninfo(o_.conninfo);
    if (o_.lab_id.empty()) throw UserError("archive: a lab id is needed to forward (archive.lab_id)");
    thread_ = std::thread([this] { run_guarded("archive forwarding", [this] { run(); }); });
}

BackgroundForwarder::~BackgroundForwarder() { stop(); }

void BackgroundForwarder::stop() {
    {
        std::lock_guard lk(m_);
        stop_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
    std::lock_guard lk(m_);
    state_ = "stopped";
    pass_done_.notify_all();
}

bool BackgroundForwarder::finish(std::chrono::milliseconds stall, const std::function<void(std::int64_t)>& progress,
                                 const std::function<bool()>& cut_short) {
    bool complete = false;
    {
        std::unique_lock lk(m_);
        if (!stop_) {
            // No wall-clock cap: a loaded machine or a big backlog takes as long as it takes, as
            // long as chunks keep being committed (issue 31: a 10-s cap left 3.1 M rows behind).
            const std::uint64_t ticket = ++requested_;
            wake_.notify_all();
            const std::int64_t added_at_start = samples_added_;
            std::int64_t last_added = samples_added_;
            auto last_progress = std::chrono::steady_clock::now();
            for (;;) {
                if (pass_done_.wait_for(lk, std::chrono::seconds(1), [&] { return served_ >= ticket; })) {
                    complete = last_ok_;
                    break;
                }
                const auto now = std::chrono::steady_clock::now();
                if (samples_added_ != last_added) last_added = samples_added_, last_progress = now;
                if (now - last_progress >= stall) break;  // the server stopped answering: the next start resumes
                const std::int64_t sent = samples_added_ - added_at_start;
                lk.unlock();
                if (progress) progress(sent);
                const bool cut = cut_short && cut_short();
                lk.lock();
                if (cut) break;
            }
        }
    }
    stop();
    return complete;
}

bool BackgroundForwarder::forward_now() {
    std::unique_lock lk(m_);
    if (stop_) return false;
    const std::uint64_t ticket = ++requested_;
    wake_.notify_all();
    pass_done_.wait(lk, [&] { return served_ >= ticket || stop_; });
    return served_ >= ticket && last_ok_;
}

void BackgroundForwarder::run() {
    auto delay = o_.interval;
    for (;;) {
        std::uint64_t serving = 0;
        {
            std::unique_lock lk(m_);
            if (stop_) return;
            serving = requested_;
        }
        const bool ok = pass();
        {
            std::unique_lock lk(m_);
            served_ = serving;
            last_ok_ = ok;
            pass_done_.notify_all();
            // Backoff while the server is away: interval, 2x, 4x ... up to max_retry_delay.
            if (ok) delay = o_.interval;
            else delay = std::min(consecutive_failures_ <= 1 ? o_.interval : delay * 2, o_.max_retry_delay);
            wake_.wait_for(lk, delay, [&] { return stop_ || requested_ > served_; });
            if (stop_) return;
        }
    }
}

bool BackgroundForwarder::pass() {
    PushOptions push_options;
    push_options.chunk_rows = o_.chunk_rows;
    push_options.lab_name = o_.lab_name;
    const auto now_steady = std::chrono::steady_clock::now();
    push_options.check_idle_log = !idle_checked_ || now_steady - idle_checked_at_ >= o_.idle_check_interval;
    push_options.after_chunk = [this](const ChunkCommitted& chunk) {
        {
            std::lock_guard lk(m_);
            samples_added_ += chunk.added;
            if (stop_) throw StopRequested{};
        }
        if (o_.after_chunk) o_.after_chunk(chunk);
    };
    // Everything committed before the snapshot push() takes is in the archive when it returns.
    const std::int64_t began_utc_ns = utc_now_ns();
    {
        std::lock_guard lk(m_);
        if (state_ == "starting" || state_ == "up to date") state_ = "forwarding";
    }
    std::string error;
    bool refused = false;
    try {
        (void)push(o_.database, o_.conninfo, o_.lab_id, push_options);
    } catch (const StopRequested&) {
        return false;
    } catch (const UserError& e) {
        error = e.what();
        refused = e.status() == ExitStatus::refused;
    } catch (const std::exception& e) {
        error = e.what();
    }

    std::string severity, message;
    {
        std::lock_guard lk(m_);
        ++passes_;
        if (error.empty()) {
            if (consecutive_failures_ > 0)
                severity = "info", message = fmt::format("archive reachable again after {} failed pass(es); forwarding "
                                                         "resumed where it stopped",
                                                         consecutive_failures_);
            else if (archived_through_utc_ns_ == 0)
                severity = "info", message = fmt::format("forwarding to the archive as lab '{}'", o_.lab_id);
            consecutive_failures_ = 0;
            archived_through_utc_ns_ = began_utc_ns;
            if (push_options.check_idle_log) idle_checked_ = true, idle_checked_at_ = now_steady;
            state_ = "up to date";  // everything committed before this pass began is in the archive
            last_error_.clear();
        } else {
            ++failures_;
            ++consecutive_failures_;
            // One notice per outage (or per new reason), not one per retry.
            if (consecutive_failures_ == 1 || error != last_error_)
                severity = refused ? "error" : "warn",
                message = fmt::format("archive forwarding failed: {}; retrying with backoff up to {} s, nothing is "
                                      "lost (the local database keeps every row)",
                                      error, o_.max_retry_delay.count() / 1000);
            state_ = refused ? "refused" : "retrying";
            last_error_ = error;
        }
    }
    if (!message.empty() && notice_) notice_(severity, message);
    return error.empty();
}

nlohmann::json BackgroundForwarder::status_json() const {
    std::lock_guard lk(m_);
    nlohmann::json j{{"state", state_},
                     {"lab_id", o_.lab_id},
                     {"passes", passes_},
                     {"failures", failures_},
                     {"samples_added", samples_added_},
                     {"last_error", last_error_.empty() ? nlohmann::json(nullptr) : nlohmann::json(last_error_)}};
    if (archived_through_utc_ns_ > 0) {
        j["archived_through_utc_ns"] = archived_through_utc_ns_;
        j["behind_s"] = static_cast<double>(utc_now_ns() - archived_through_utc_ns_) * 1e-9;
    } else {
        j["archived_through_utc_ns"] = nullptr;
        j["behind_s"] = nullptr;
    }
    return j;
}

}  // namespace manikind::archive
