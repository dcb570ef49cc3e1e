#pragma once
// The Recorder's crash ring: every accepted sample is copied into a memory-mapped file in
// shared memory (/dev/shm by default) until its transaction commits. The file lives in the
// kernel's memory, not on the disk, so it costs no disk writes, and it outlives the process:
// a daemon that is killed or crashes leaves its uncommitted samples there, and the next
// Recorder on the same database stores them before anything else. That is what lets the
// Recorder commit rarely (docs/recorder.md, "Write amplification") without a crash of the
// daemon costing data. A power cut or kernel crash empties it; see "Durability".
//
// One writer per ring: the file is locked (flock) while open, and a second Recorder on the
// same database runs without a ring (it says so) rather than share it.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <vector>

#include "store/database.hpp"

namespace manikind::recorder {

class CrashRing {
public:
    // The ring for `db_path` in `dir` (a file named after the database's device and inode),
    // holding at most `capacity` samples not yet committed. Nullopt, with the reason in
    // `why_not`, when the directory is unusable or another process holds the ring.
    static std::optional<CrashRing> open(const std::filesystem::path& dir, const std::filesystem::path& db_path,
                                         std::size_t capacity, std::string& why_not);
    CrashRing(CrashRing&&) noexcept;
    CrashRing& operator=(CrashRing&&) noexcept;
    ~CrashRing();  // unmaps and unlocks; the file stays (with nothing pending after a clean stop)

    // The samples a previous writer accepted and never saw committed, oldest first.
    std::vector<SampleRow> pending() const;
    // Forgets every sample: call once pending() is stored.
    void clear();

    // Appends one sample (the caller serialises appends and keeps fewer than capacity() pending).
    void append(const SampleRow& row) noexcept;
    // The oldest `n` pending samples are stored (committed, or given up): they leave the ring.
    void resolved(std::size_t n) noexcept;
    std::size_t capacity() const noexcept { return capacity_; }
    const std::filesystem::path& path() const noexcept { return path_; }

private:
    struct Header;
    struct Record;
    CrashRing() = default;
    Header* header() const noexcept;
    Record* records() const noexcept;

    std::filesystem::path path_;
    int fd_ = -1;
    void* map_ = nullptr;
    std::size_t map_bytes_ = 0;
    std::size_t capacity_ = 0;
};

}  // namespace manikind::recorder
