#pragma once
// One daemon per database and per control socket: an exclusive flock(2) on "<path>.lock", held
// for the daemon's life and released by the kernel when the process ends (also on kill -9), so a
// crashed daemon never leaves a lock behind. The holder's PID is written into the file, so a
// second daemon is refused with it.
#include <filesystem>
#include <string>

namespace manikind {

class InstanceLock {
public:
    InstanceLock() = default;
    // Takes the lock on `path` + ".lock" or throws UserError naming what is locked, the lock file
    // and the holder's PID. `what` is "database" or "control socket".
    static InstanceLock acquire(const std::filesystem::path& path, const std::string& what);
    InstanceLock(InstanceLock&& other) noexcept;
    InstanceLock& operator=(InstanceLock&& other) noexcept;
    InstanceLock(const InstanceLock&) = delete;
    InstanceLock& operator=(const InstanceLock&) = delete;
    ~InstanceLock();

    bool held() const { return fd_ >= 0; }
    const std::filesystem::path& lock_file() const { return lock_file_; }

private:
    int fd_ = -1;
    std::filesystem::path lock_file_;
};

}  // namespace manikind
