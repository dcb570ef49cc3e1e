#pragma once
// Store and forward (issue 19, docs/archive.md): a daemon's SQLite file stays the source of truth;
// push() copies what it holds into the shared PostgreSQL archive. Sending a row twice changes
// nothing there, and samples go in chunks each committed together with the progress row, so a
// push cut off at any point (server stopped, network gone, process killed) is finished by running
// it again: nothing lost, nothing doubled.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

namespace manikind::archive {

// What one table's rows did: sent to the server, and of those, added or changed there.
struct TableCounts {
    std::int64_t sent = 0;
    std::int64_t added = 0;
};

// One chunk of one trial's samples, committed with its progress.
struct ChunkCommitted {
    std::string trial_uuid;
    std::int64_t rows = 0;
    std::int64_t added = 0;
};

struct PushOptions {
    std::size_t chunk_rows = 50'000;  // samples (and idle samples) per transaction
    std::string lab_name;             // labs.name for a lab the archive has not seen; empty: the lab id
    // Called after every committed chunk (progress output; tests stop the server here).
    std::function<void(const ChunkCommitted&)> after_chunk;
    // Count the idle log up to its progress key to catch rows written behind it (a wall clock
    // stepped back): one scan of the log, which grows for as long as the lab records. The daemon's
    // forwarder asks for it at its first pass and then hourly, not at every 5-s pass.
    bool check_idle_log = true;
};

struct PushResult {
    std::string archive;  // "host:port/dbname"
    std::string lab_id;
    int archive_schema_version = 0;
    TableCounts campaigns, trials, channels, events, samples;
    TableCounts devices, results, twin_versions, idle_samples;
    TableCounts setups;  // lab, chamber, manikin, calibration, configuration (recorder schema v7)
    TableCounts notes;   // the lab notebook (recorder schema v9)
    std::int64_t chunks = 0;       // of samples
    std::int64_t chunks_resent = 0;  // sent plainly, met a row already there, sent again with ON CONFLICT
    std::int64_t idle_chunks = 0;  // of idle_samples
    bool idle_resent = false;      // rows appeared behind the idle log's progress (clock stepped back): resent all
    std::int64_t trials_complete = 0;  // terminal trials whose samples the archive now holds in full
    std::int64_t trials_partial = 0;   // trials still running: sent up to what was committed
};

// Reads `sqlite_path` read-only (a daemon may be writing it), one snapshot for the whole push.
// Throws UserError: status 2 for a missing or foreign file, a bad lab id or conninfo; 3 when the
// server cannot be reached or the connection drops (run again to resume); 4 when the server
// refuses (permissions, a trial UUID another lab owns, a newer archive schema, a push of the
// same lab already running).
PushResult push(const std::filesystem::path& sqlite_path, const std::string& conninfo, const std::string& lab_id,
                const PushOptions& options = {});

}  // namespace manikind::archive
