#include "daemon/instance_lock.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

#include <fmt/format.h>

#include "base/user_error.hpp"

namespace manikind {

InstanceLock InstanceLock::acquire(const std::filesystem::path& path, const std::string& what) {
    InstanceLock lock;
    lock.lock_file_ = path.string() + ".lock";
    const std::string file = lock.lock_file_.string();
    // O_NOFOLLOW: a symlink planted at the lock path must not make us create or truncate its target.
    lock.fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_NOFOLLOW | O_CLOEXEC, 0640);
    if (lock.fd_ < 0)
        throw UserError(fmt::format("cannot open the {} lock {}: {}", what, file, std::strerror(errno)));
    if (::flock(lock.fd_, LOCK_EX | LOCK_NB) != 0) {
        const int err = errno;
        char pid[32] = {};
        const ssize_t n = ::pread(lock.fd_, pid, sizeof pid - 1, 0);
        std::string holder = n > 0 ? std::string(pid, static_cast<std::size_t>(n)) : std::string("?");
        while (!holder.empty() && (holder.back() == '\n' || holder.back() == ' ')) holder.pop_back();
        ::close(lock.fd_);
        lock.fd_ = -1;
        if (err == EWOULDBLOCK)
            throw UserError(fmt::format("the {} {} is in use by another manikind (PID {}; lock {}): stop it first, "
                                        "or give this one its own --database and --socket",
                                        what, path.string(), holder, file));
        throw UserError(fmt::format("cannot lock the {} {} ({}): {}", what, path.string(), file, std::strerror(err)));
    }
    const std::string pid = std::to_string(::getpid()) + "\n";
    if (::ftruncate(lock.fd_, 0) != 0 || ::pwrite(lock.fd_, pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size()))
        throw UserError(fmt::format("cannot write the {} lock {}: {}", what, file, std::strerror(errno)));
    return lock;
}

InstanceLock::InstanceLock(InstanceLock&& other) noexcept : fd_(other.fd_), lock_file_(std::move(other.lock_file_)) {
    other.fd_ = -1;
}

InstanceLock& InstanceLock::operator=(InstanceLock&& other) noexcept {
    if (this != &other) {
        if (fd_ >= 0) ::close(fd_);
        fd_ = other.fd_;
        lock_file_ = std::move(other.lock_file_);
        other.fd_ = -1;
    }
    return *this;
}

// The file stays: unlinking a lock file lets a third process lock a fresh inode while a second
// still holds the old one. Closing releases the lock.
InstanceLock::~InstanceLock() {
    if (fd_ >= 0) ::close(fd_);
}

}  // namespace manikind
