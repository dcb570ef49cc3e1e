#include "base/toml_input.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fmt/core.h>

#include "base/user_error.hpp"

namespace manikind::toml_input {
namespace {

std::string file_kind(mode_t mode) {
    if (S_ISDIR(mode)) return "a directory";
    if (S_ISCHR(mode)) return "a character device";
    if (S_ISBLK(mode)) return "a block device";
    if (S_ISFIFO(mode)) return "a FIFO";
    if (S_ISSOCK(mode)) return "a socket";
    return "not a regular file";
}

std::string size_text(std::uintmax_t bytes) {
    const double b = static_cast<double>(bytes);
    if (b >= 1024.0 * 1024.0 * 1024.0) return fmt::format("{:.1f} GiB ({} bytes)", b / (1024.0 * 1024.0 * 1024.0), bytes);
    if (b >= 1024.0 * 1024.0) return fmt::format("{:.1f} MiB ({} bytes)", b / (1024.0 * 1024.0), bytes);
    if (b >= 1024.0) return fmt::format("{:.1f} KiB ({} bytes)", b / 1024.0, bytes);
    return fmt::format("{} bytes", bytes);
}

std::string limit_text(std::uintmax_t bytes) {
    if (bytes > 0 && bytes % (1024 * 1024) == 0) return fmt::format("{} MiB", bytes / (1024 * 1024));
    if (bytes > 0 && bytes % 1024 == 0) return fmt::format("{} KiB", bytes / 1024);
    return fmt::format("{} bytes", bytes);
}

// Closes the descriptor on every path out of read_text_file.
struct FdGuard {
    int fd;
    ~FdGuard() {
        if (fd >= 0) ::close(fd);
    }
};

}  // namespace

toml::table parse(const std::string& text, const std::string& source_name) {
    try {
        return toml::parse(text, source_name);
    } catch (const toml::parse_error& e) {
        throw UserError(fmt::format("{}: {}", where(source_name, e.source()), e.description()));
    }
}

std::string where(const std::string& source_name, const toml::source_region& region) {
    return fmt::format("{}:{}:{}", source_name, region.begin.line, region.begin.column);
}

std::string read_text_file(const std::filesystem::path& path, const std::string& what, std::uintmax_t max_bytes) {
    const std::string name = path.string();
    const auto refuse_kind = [&](mode_t mode) {
        if (S_ISDIR(mode)) return UserError(fmt::format("{}: is a directory, expected {}", name, what));
        return UserError(fmt::format("{}: is {}, not a regular file (expected {})", name, file_kind(mode), what));
    };
    const auto over_limit = [&](const std::string& size) {
        return UserError(fmt::format("{}: {} is over the {} limit for {}", name, size, limit_text(max_bytes), what));
    };
    // stat first: opening a FIFO would block and /dev/zero never ends.
    struct stat st {};
    if (::stat(name.c_str(), &st) != 0)
        throw UserError(fmt::format("{}: cannot open {}: {}", name, what, std::strerror(errno)));
    if (!S_ISREG(st.st_mode)) throw refuse_kind(st.st_mode);
    if (static_cast<std::uintmax_t>(st.st_size) > max_bytes) throw over_limit(size_text(static_cast<std::uintmax_t>(st.st_size)));
    // O_NONBLOCK: the path may have been swapped for a FIFO since the stat; fstat says what we opened.
    FdGuard in{::open(name.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY)};
    if (in.fd < 0) throw UserError(fmt::format("{}: cannot open {}: {}", name, what, std::strerror(errno)));
    if (::fstat(in.fd, &st) != 0 || !S_ISREG(st.st_mode)) throw refuse_kind(st.st_mode);
    // At most max_bytes + 1: one byte more than allowed is enough to know the file is too big.
    std::string text;
    char buf[16384];
    for (;;) {
        const std::uintmax_t room = max_bytes + 1 - text.size();
        const ssize_t n = ::read(in.fd, buf, static_cast<std::size_t>(std::min<std::uintmax_t>(sizeof buf, room)));
        if (n < 0) {
            if (errno == EINTR) continue;
            throw UserError(fmt::format("{}: cannot read {}: {}", name, what, std::strerror(errno)));
        }
        if (n == 0) break;
        text.append(buf, static_cast<std::size_t>(n));
        if (text.size() > max_bytes) throw over_limit("more than " + size_text(max_bytes));
    }
    return text;
}

std::optional<std::string> read_file(const std::filesystem::path& path) {
    try {
        return read_text_file(path, "a TOML file");
    } catch (const UserError&) {
        return std::nullopt;
    }
}

}  // namespace manikind::toml_input
