#include "sim/devices/pty_endpoint.hpp"

#include <fcntl.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace manikind::sim {

PtyEndpoint::PtyEndpoint(std::filesystem::path link_path) : link_path_(std::move(link_path)) { open_pty(); }

PtyEndpoint::~PtyEndpoint() {
    close_pty();
    std::error_code ec;
    std::filesystem::remove(link_path_, ec);
}

void PtyEndpoint::open_pty() {
    char name[256] = {};
    termios raw{};
    cfmakeraw(&raw);  // no echo, no CR/LF translation: bytes pass as the instrument sends them
    if (::openpty(&master_, &slave_, name, &raw, nullptr) != 0)
        throw std::runtime_error(std::string("openpty: ") + std::strerror(errno));
    ::fcntl(master_, F_SETFL, ::fcntl(master_, F_GETFL) | O_NONBLOCK);
    ::fcntl(master_, F_SETFD, FD_CLOEXEC);
    ::fcntl(slave_, F_SETFD, FD_CLOEXEC);
    slave_path_ = name;
    // Point the stable name at the new slave atomically.
    const auto tmp = link_path_.string() + ".new";
    std::filesystem::remove(tmp);
    std::filesystem::create_symlink(slave_path_, tmp);
    std::filesystem::rename(tmp, link_path_);
}

void PtyEndpoint::close_pty() {
    if (slave_ >= 0) ::close(slave_);
    if (master_ >= 0) ::close(master_);
    slave_ = master_ = -1;
}

std::size_t PtyEndpoint::write(const std::string& bytes) {
    std::size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::write(master_, bytes.data() + done, bytes.size() - done);
        if (n <= 0) break;  // EAGAIN: the line's buffer is full
        done += static_cast<std::size_t>(n);
    }
    bytes_written_ += done;
    return done;
}

std::string PtyEndpoint::read_available() {
    std::string out;
    char buf[256];
    for (;;) {
        const ssize_t n = ::read(master_, buf, sizeof buf);
        if (n <= 0) break;
        out.append(buf, static_cast<std::size_t>(n));
    }
    return out;
}

void PtyEndpoint::hang_up_and_reopen() {
    close_pty();
    open_pty();
}

}  // namespace manikind::sim
