#pragma once
// The daemon's own store and forward (`[archive] postgresql`, docs/archive.md): a thread that runs
// push() on the recorder's file every few seconds while the server answers, and backs off while
// it does not. It reads the file through its own read-only connection, so acquisition and the
// recorder never wait for it or for the network. What an outage held back goes at the next pass
// that reaches the server: push() resumes from the progress the archive keeps.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "archive/forwarder.hpp"

namespace manikind::archive {

struct ForwardingOptions {
    std::filesystem::path database;
    std::string conninfo;
    std::string lab_id;
    std::string lab_name;
    std::chrono::milliseconds interval{5000};          // between passes while the server answers
    std::chrono::milliseconds max_retry_delay{60000};  // the backoff's cap while it does not
    std::size_t chunk_rows = 50'000;
    // How often a pass also checks the idle log for rows behind its progress (PushOptions::check_idle_log).
    std::chrono::milliseconds idle_check_interval{3'600'000};
    // Tests: called after each committed chunk, as PushOptions::after_chunk.
    std::function<void(const ChunkCommitted&)> after_chunk;
};

// One line for the daemon's event log: severity "info" | "warn" | "error", kind "archive".
using ForwardingNotice = std::function<void(const std::string& severity, const std::string& message)>;

class BackgroundForwarder {
public:
    // Starts the thread; its first pass runs at once. UserError for a conninfo that does not parse
    // or a bad lab id (the daemon refuses to start rather than forward nowhere).
    BackgroundForwarder(ForwardingOptions options, ForwardingNotice notice);
    ~BackgroundForwarder();
    BackgroundForwarder(const BackgroundForwarder&) = delete;
    BackgroundForwarder& operator=(const BackgroundForwarder&) = delete;

    // Ends the thread; a pass under way stops after its current chunk (the next start resumes).
    void stop();
    // At shutdown, after the recorder's last commit: one more pass, waited for as long as it makes
    // progress (a chunk committed within `stall`), reporting rows sent through `progress` about
    // once a second; `cut_short` (a second signal) ends the wait. Then stop(). Returns true when
    // everything committed locally is in the archive; false when cut short or stalled (the next
    // start sends the rest: nothing is lost).
    bool finish(std::chrono::milliseconds stall, const std::function<void(std::int64_t rows_sent)>& progress = {},
                const std::function<bool()>& cut_short = {});

    // Runs a pass now and waits for it: true when it reached the server and sent everything
    // committed before it began. (Tests, and `manikin archive` status checks.)
    bool forward_now();

    // For the daemon's status: state ("forwarding" | "retrying" | "refused" | "stopped"), passes,
    // failures, samples added, the time everything committed locally was known to be in the archive
    // (`archived_through_utc_ns`) and how far that is behind now (`behind_s`), the last error.
    nlohmann::json status_json() const;

private:
    void run();
    bool pass();

    ForwardingOptions o_;
    ForwardingNotice notice_;
    mutable std::mutex m_;
    std::condition_variable wake_;
    std::condition_variable pass_done_;
    bool stop_ = false;
    std::uint64_t requested_ = 0;  // forward_now() requests; a pass serves every request made before it began
    std::uint64_t served_ = 0;
    bool last_ok_ = false;
    std::string state_ = "starting";  // until the first pass ends; "forwarding" while a pass sends rows
    std::uint64_t passes_ = 0, failures_ = 0, consecutive_failures_ = 0;
    std::int64_t samples_added_ = 0;
    std::int64_t archived_through_utc_ns_ = 0;  // 0: not yet
    std::chrono::steady_clock::time_point idle_checked_at_{};  // the last pass that checked and succeeded
    bool idle_checked_ = false;
    std::string last_error_;
    std::thread thread_;
};

}  // namespace manikind::archive
