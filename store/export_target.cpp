#include "store/export_target.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <random>

#include <fmt/format.h>

#include "base/user_error.hpp"

namespace manikind {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void refuse(const fs::path& out, const std::string& why) {
    throw UserError(fmt::format("{}: {}", out.string(), why), "output_refused");
}

bool same_file(const struct stat& a, const fs::path& b) {
    struct stat sb {};
    return ::stat(b.c_str(), &sb) == 0 && a.st_dev == sb.st_dev && a.st_ino == sb.st_ino;
}

// The files SQLite keeps beside a database <db>: named <db><suffix>.
struct Companion {
    const char* suffix;
    const char* what;
};
constexpr Companion kCompanions[] = {{"-wal", "the write-ahead log"},
                                     {"-shm", "the shared-memory index"},
                                     {"-journal", "the rollback journal"}};

// The path with every symbolic link resolved as far as it exists (the rest as named): what a
// write would reach.
fs::path resolved(const fs::path& p) {
    std::error_code ec;
    fs::path r = fs::weakly_canonical(p, ec);
    if (ec) r = fs::absolute(p, ec).lexically_normal();
    return r;
}

// What the first bytes of a regular file say it is; empty when not SQLite's. The headers: a
// database "SQLite format 3\0", a write-ahead log 0x377f0682/3 big-endian, a rollback journal
// d9 d5 05 f9 20 a1 63 d7 (sqlite.org/fileformat.html).
std::string database_header(const fs::path& p) {
    struct stat st {};
    if (::stat(p.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return {};
    const int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) return {};
    unsigned char b[16] = {};
    const ssize_t n = ::read(fd, b, sizeof b);
    ::close(fd);
    static const unsigned char kJournal[8] = {0xd9, 0xd5, 0x05, 0xf9, 0x20, 0xa1, 0x63, 0xd7};
    if (n >= 16 && std::memcmp(b, "SQLite format 3", 16) == 0) return "an SQLite database";
    if (n >= 4) {
        const std::uint32_t magic = (std::uint32_t{b[0]} << 24) | (std::uint32_t{b[1]} << 16) | (std::uint32_t{b[2]} << 8) | b[3];
        if (magic == 0x377f0682u || magic == 0x377f0683u) return "an SQLite write-ahead log (by its header)";
    }
    if (n >= 8 && std::memcmp(b, kJournal, sizeof kJournal) == 0) return "an SQLite rollback journal (by its header)";
    return {};
}

// "<db>-wal" where <db> exists: that database's companion, whatever its bytes (an empty -shm,
// a crashed daemon's -wal before any reader recovered it, a journal SQLite zeroed).
void refuse_companion_name(const fs::path& shown, const fs::path& p) {
    const std::string name = p.filename().string();
    for (const auto& c : kCompanions) {
        const std::string suffix = c.suffix;
        if (name.size() <= suffix.size() || !name.ends_with(suffix)) continue;
        const fs::path db = p.parent_path() / name.substr(0, name.size() - suffix.size());
        struct stat st {};
        if (::lstat(db.c_str(), &st) == 0)
            refuse(shown, fmt::format("is {} of the database {}: an output never writes over a database or its "
                                      "companions, --force or not",
                                      c.what, db.string()));
    }
}

// An earlier export: campaign.json and trials/, nothing else.
bool looks_like_export(const fs::path& folder, std::string& stranger) {
    for (const auto& e : fs::directory_iterator(folder)) {
        const auto name = e.path().filename().string();
        if ((name == "campaign.json" && e.is_regular_file()) || (name == "trials" && e.is_directory())) continue;
        stranger = name;
        return false;
    }
    return fs::exists(folder / "campaign.json");
}

// fsync of one file or folder; a failure (EIO, a full disk found late) is the export's error.
void sync_path(const fs::path& p) {
    const int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw UserError(fmt::format("{}: cannot open to flush: {}", p.string(), std::strerror(errno)), "write_failed");
    const int rc = ::fsync(fd);
    const int err = errno;
    ::close(fd);
    if (rc != 0 && err != EINVAL)  // EINVAL: a file system that cannot sync (nothing to lose)
        throw UserError(fmt::format("{}: writing to the disk failed: {}", p.string(), std::strerror(err)), "write_failed");
}

void sync_tree(const fs::path& p) {
    if (fs::is_directory(p))
        for (const auto& e : fs::recursive_directory_iterator(p))
            if (e.is_regular_file() || e.is_directory()) sync_path(e.path());
    sync_path(p);
}

}  // namespace

void refuse_protected_output(const fs::path& out, const std::vector<fs::path>& inputs) {
    if (out.empty()) refuse(out, "an empty output path");
    const fs::path real = resolved(out);
    struct stat st {};
    const bool exists = ::stat(real.c_str(), &st) == 0;
    for (const auto& in : inputs) {
        const fs::path real_in = resolved(in);
        struct stat in_st {};
        if (::stat(real_in.c_str(), &in_st) == 0 && S_ISDIR(in_st.st_mode)) {
            // A campaign folder read: everything in it is the recording (campaign.json, trials/).
            const fs::path inside = real.lexically_relative(real_in);
            if (!inside.empty() && *inside.begin() != "..")
                refuse(out, fmt::format("is inside the campaign folder {} this command reads: an output never lands in a "
                                        "recording it reads, --force or not; name a path outside it",
                                        in.string()));
            continue;
        }
        if ((exists && same_file(st, real_in)) || real == real_in)
            refuse(out, fmt::format("is {}, which this command reads: an output never writes over its input, --force or not",
                                    in.string()));
        for (const auto& c : kCompanions) {
            const fs::path companion = real_in.string() + c.suffix;
            if ((exists && same_file(st, companion)) || real == companion)
                refuse(out, fmt::format("is {} of the database {}, which this command reads: an output never writes over a "
                                        "database or its companions, --force or not",
                                        c.what, in.string()));
        }
    }
    if (exists) {
        const std::string header = database_header(real);
        if (!header.empty())
            refuse(out, fmt::format("is {}: an output never writes over a database or its companions, --force or not", header));
    }
    // By name: as given (a link named so) and where it leads.
    refuse_companion_name(out, fs::absolute(out).lexically_normal());
    refuse_companion_name(out, real);
}

ExportTarget::ExportTarget(fs::path out, ExportShape shape, bool force, const std::vector<fs::path>& inputs)
    : out_(std::move(out)), shape_(shape) {
    if (out_.empty()) refuse(out_, "an empty output path");
    if (out_.filename().empty() || out_.filename() == "." || out_.filename() == "..") out_ = fs::absolute(out_).lexically_normal();
    while (!out_.empty() && out_.filename().empty()) out_ = out_.parent_path();  // "out/" -> "out"
    const char* wanted = shape_ == ExportShape::file ? "a file" : "a folder";
    struct stat st {};
    refuse_protected_output(out_, inputs);
    if (::lstat(out_.c_str(), &st) == 0) {
        if (S_ISLNK(st.st_mode)) refuse(out_, "is a symbolic link: name the real path");
        if (S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode)) refuse(out_, "is a device, not a file: an export never writes to one");
        if (S_ISFIFO(st.st_mode) || S_ISSOCK(st.st_mode)) refuse(out_, "is a FIFO or socket, not a file");
        if (S_ISREG(st.st_mode)) {
            if (shape_ == ExportShape::folder)
                refuse(out_, "is a file, and a CSV export is a folder (campaign.json and trials/): name a new folder");
            if (!force) refuse(out_, "exists; --force replaces it with the export");
            replace_ = true;
        } else if (S_ISDIR(st.st_mode)) {
            if (shape_ == ExportShape::file)
                refuse(out_, "is a folder, and an HDF5 export is one file: name the file, e.g. " +
                                 (out_ / "campaign.h5").string());
            std::string stranger;
            if (fs::is_empty(out_)) {
                replace_ = true;  // an empty folder named for the export: fill it
            } else if (!looks_like_export(out_, stranger)) {
                refuse(out_, stranger.empty() ? "exists and is not an export (no campaign.json): not replaced"
                                              : fmt::format("holds '{}', which is not part of an export: not replaced, "
                                                            "--force or not", stranger));
            } else if (!force) {
                refuse(out_, "holds an earlier export; --force replaces it");
            } else {
                replace_ = true;
            }
        } else {
            refuse(out_, fmt::format("is neither a file nor a folder; {} is wanted", wanted));
        }
    } else if (errno != ENOENT) {
        refuse(out_, fmt::format("cannot be examined: {}", std::strerror(errno)));
    }
    const fs::path parent = out_.has_parent_path() ? out_.parent_path() : fs::path(".");
    std::error_code ec;
    fs::create_directories(parent, ec);
    if (ec) refuse(out_, fmt::format("cannot create the folder {}: {}", parent.string(), ec.message()));
    std::random_device rd;
    staging_ = parent / fmt::format(".{}.partial-{}-{:08x}", out_.filename().string(), ::getpid(), rd());
}

ExportTarget::~ExportTarget() {
    if (committed_) return;
    std::error_code ignored;
    fs::remove_all(staging_, ignored);
}

void ExportTarget::commit() {
    sync_tree(staging_);
    const fs::path parent = staging_.parent_path();
    if (replace_ && shape_ == ExportShape::folder) {
        // The old export stays whole until the new one has its name.
        const fs::path old = parent / fmt::format(".{}.replaced-{}", out_.filename().string(), ::getpid());
        std::error_code ec;
        fs::rename(out_, old, ec);
        if (ec) throw UserError(fmt::format("{}: cannot move the earlier export aside: {}", out_.string(), ec.message()), "write_failed");
        fs::rename(staging_, out_, ec);
        if (ec) {
            fs::rename(old, out_);
            throw UserError(fmt::format("{}: cannot rename the export into place: {}", out_.string(), ec.message()), "write_failed");
        }
        fs::remove_all(old, ec);
    } else {
        // Checked again at the last moment: what appeared since is not written over.
        if (!replace_ && ::renameat2(AT_FDCWD, staging_.c_str(), AT_FDCWD, out_.c_str(), RENAME_NOREPLACE) != 0)
            throw UserError(fmt::format("{}: cannot rename the export into place: {}", out_.string(), std::strerror(errno)),
                            "write_failed");
        if (replace_) {
            if (const std::string header = database_header(out_); shape_ == ExportShape::file && !header.empty())
                refuse(out_, fmt::format("became {} while the export was written: not replaced", header));
            std::error_code ec;
            fs::rename(staging_, out_, ec);
            if (ec) throw UserError(fmt::format("{}: cannot rename the export into place: {}", out_.string(), ec.message()),
                                    "write_failed");
        }
    }
    committed_ = true;
    sync_path(parent);
}

}  // namespace manikind
