#pragma once
// The instrument side of a serial line in the simulated lab: a pseudo-terminal whose slave
// path the driver opens like any /dev/ttyUSB*. A stable symlink (`link_path`) points at the
// current slave, as /dev/serial/by-id does for real adapters, so a "cable pulled" fault can
// hang the line up and bring up a new one behind the same name.
#include <cstdint>
#include <filesystem>
#include <string>

namespace manikind::sim {

class PtyEndpoint {
public:
    explicit PtyEndpoint(std::filesystem::path link_path);
    ~PtyEndpoint();
    PtyEndpoint(const PtyEndpoint&) = delete;
    PtyEndpoint& operator=(const PtyEndpoint&) = delete;

    const std::filesystem::path& link_path() const { return link_path_; }
    const std::string& slave_path() const { return slave_path_; }

    // Writes what fits without blocking; returns the bytes written (the rest is lost, as on a
    // real line with nobody listening).
    std::size_t write(const std::string& bytes);
    // Whatever the host sent (polled mode commands), without blocking.
    std::string read_available();
    // The master side, for a caller that polls several lines at once before reading.
    int fd() const { return master_; }
    // Hangs the line up (the driver's reads fail) and opens a fresh pty behind the same link.
    void hang_up_and_reopen();

    std::uint64_t bytes_written() const { return bytes_written_; }

private:
    void open_pty();
    void close_pty();

    std::filesystem::path link_path_;
    std::string slave_path_;
    int master_ = -1;
    int slave_ = -1;   // kept open so the line stays up while the driver reconnects
    std::uint64_t bytes_written_ = 0;
};

}  // namespace manikind::sim
