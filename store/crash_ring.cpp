#include "store/crash_ring.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <new>
#include <system_error>
#include <functional>
#include <utility>

#include <fmt/core.h>

namespace manikind::recorder {

namespace {
constexpr char ring_magic[8] = {'M', 'K', 'R', 'I', 'N', 'G', '0', '1'};
}

// Written once at creation except head and tail. A record is complete before head counts it
// (release store), so a process killed mid-append leaves at most that record uncounted, and it
// was not yet accepted either.
struct CrashRing::Header {
    char magic[8];
    std::uint64_t capacity;
    std::uint64_t record_bytes;
    std::uint64_t db_device;
    std::uint64_t db_inode;
    std::atomic<std::uint64_t> head;  // samples appended since the last clear()
    std::atomic<std::uint64_t> tail;  // of which stored (committed or given up)
    std::uint64_t reserved;
};
static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "the ring's counters are shared through a file mapping");

struct CrashRing::Record {
    std::int64_t trial_id, channel_id, mono_ns, utc_ns;
    double value;
    std::int64_t quality;
};

CrashRing::Header* CrashRing::header() const noexcept {
    static_assert(sizeof(Header) == 64 && sizeof(Record) == 48, "the file layout");
    return static_cast<Header*>(map_);
}
CrashRing::Record* CrashRing::records() const noexcept {
    return reinterpret_cast<Record*>(static_cast<char*>(map_) + sizeof(Header));
}

std::optional<CrashRing> CrashRing::open(const std::filesystem::path& dir, const std::filesystem::path& db_path,
                                         std::size_t capacity, std::string& why_not) {
    struct stat db_stat {};
    if (::stat(db_path.c_str(), &db_stat) != 0) {
        why_not = fmt::format("{}: {}", db_path.string(), std::strerror(errno));
        return std::nullopt;
    }
    // Named after the database file itself (device and inode) and its path, so two databases
    // never share a ring and a ring is found again whatever path the next daemon is given.
    std::error_code ec;
    auto canonical = std::filesystem::weakly_canonical(db_path, ec);
    if (ec) canonical = db_path;
    const auto path_hash = std::hash<std::string>{}(canonical.string());
    CrashRing ring;
    ring.path_ = dir / fmt::format("manikind-recorder-{:x}-{:x}-{:08x}.ring", static_cast<std::uint64_t>(db_stat.st_dev),
                                   static_cast<std::uint64_t>(db_stat.st_ino), path_hash & 0xffffffffu);
    ring.capacity_ = std::max<std::size_t>(capacity, 1);
    ring.map_bytes_ = sizeof(Header) + ring.capacity_ * sizeof(Record);
    const auto fail = [&](std::string_view what) {
        why_not = fmt::format("{}: {}: {}", ring.path_.string(), what, std::strerror(errno));
        return std::nullopt;
    };
    ring.fd_ = ::open(ring.path_.c_str(), O_RDWR | O_CREAT | O_NOFOLLOW | O_CLOEXEC, 0600);
    if (ring.fd_ < 0) return fail("cannot open");
    if (::flock(ring.fd_, LOCK_EX | LOCK_NB) != 0) {
        if (errno == EWOULDBLOCK) {
            why_not = fmt::format("{}: held by another process recording into {}", ring.path_.string(), db_path.string());
            return std::nullopt;
        }
        return fail("cannot lock");
    }
    struct stat ring_stat {};
    if (::fstat(ring.fd_, &ring_stat) != 0) return fail("cannot stat");
    if (ring_stat.st_uid != ::geteuid()) {
        errno = EPERM;
        return fail("owned by another user");
    }
    // Keep what a previous writer left if it has the same shape; otherwise start afresh.
    std::vector<SampleRow> left;
    bool reuse = false;
    if (static_cast<std::size_t>(ring_stat.st_size) >= sizeof(Header)) {
        Header old{};
        // A ring this code wrote for this database file; its capacity may differ (another queue size).
        const bool ours = ::pread(ring.fd_, &old, sizeof(Header), 0) == static_cast<ssize_t>(sizeof(Header)) &&
                          std::memcmp(old.magic, ring_magic, sizeof ring_magic) == 0 && old.record_bytes == sizeof(Record) &&
                          old.db_device == static_cast<std::uint64_t>(db_stat.st_dev) &&
                          old.db_inode == static_cast<std::uint64_t>(db_stat.st_ino) &&
                          static_cast<std::size_t>(ring_stat.st_size) == sizeof(Header) + old.capacity * sizeof(Record);
        if (ours && old.capacity == ring.capacity_)
            reuse = true;
        else if (ours && old.tail.load() <= old.head.load() && old.head.load() - old.tail.load() <= old.capacity) {
            // Another queue size: read what is pending at the old size, then resize.
            for (std::uint64_t seq = old.tail.load(); seq < old.head.load(); ++seq) {
                Record r{};
                if (::pread(ring.fd_, &r, sizeof r, static_cast<off_t>(sizeof(Header) + (seq % old.capacity) * sizeof(Record))) !=
                    static_cast<ssize_t>(sizeof r))
                    break;
                left.push_back({r.trial_id, r.channel_id, r.mono_ns, r.utc_ns, r.value, static_cast<std::uint8_t>(r.quality)});
            }
        }
    }
    if (!reuse) {
        if (::ftruncate(ring.fd_, 0) != 0) return fail("cannot truncate");
        if (left.size() > ring.capacity_) {  // never fewer places than what is left to store
            ring.capacity_ = left.size();
            ring.map_bytes_ = sizeof(Header) + ring.capacity_ * sizeof(Record);
        }
    }
    // Reserved up front: a write into a mapping of a full tmpfs would kill the process (SIGBUS).
    if (const int rc = ::posix_fallocate(ring.fd_, 0, static_cast<off_t>(ring.map_bytes_)); rc != 0) {
        errno = rc;
        return fail(fmt::format("cannot reserve {} MB", ring.map_bytes_ >> 20));
    }
    ring.map_ = ::mmap(nullptr, ring.map_bytes_, PROT_READ | PROT_WRITE, MAP_SHARED, ring.fd_, 0);
    if (ring.map_ == MAP_FAILED) {
        ring.map_ = nullptr;
        return fail("cannot map");
    }
    Header* h = ring.header();
    if (!reuse) {
        std::memcpy(h->magic, ring_magic, sizeof ring_magic);
        h->capacity = ring.capacity_;
        h->record_bytes = sizeof(Record);
        h->db_device = static_cast<std::uint64_t>(db_stat.st_dev);
        h->db_inode = static_cast<std::uint64_t>(db_stat.st_ino);
        h->head.store(0);
        h->tail.store(0);
        for (const auto& row : left) ring.append(row);
    } else if (h->tail.load() > h->head.load() || h->head.load() - h->tail.load() > ring.capacity_) {
        h->head.store(0);  // counters that make no sense: nothing trustworthy to recover
        h->tail.store(0);
    }
    return ring;
}

CrashRing::CrashRing(CrashRing&& o) noexcept
    : path_(std::move(o.path_)),
      fd_(std::exchange(o.fd_, -1)),
      map_(std::exchange(o.map_, nullptr)),
      map_bytes_(o.map_bytes_),
      capacity_(o.capacity_) {}

CrashRing& CrashRing::operator=(CrashRing&& o) noexcept {
    if (this != &o) {
        this->~CrashRing();
        new (this) CrashRing(std::move(o));
    }
    return *this;
}

CrashRing::~CrashRing() {
    if (map_) ::munmap(map_, map_bytes_);
    if (fd_ >= 0) ::close(fd_);  // releases the lock
}

std::vector<SampleRow> CrashRing::pending() const {
    std::vector<SampleRow> rows;
    const Header* h = header();
    for (std::uint64_t seq = h->tail.load(std::memory_order_acquire); seq < h->head.load(std::memory_order_acquire); ++seq) {
        const Record& r = records()[seq % capacity_];
        rows.push_back({r.trial_id, r.channel_id, r.mono_ns, r.utc_ns, r.value, static_cast<std::uint8_t>(r.quality)});
    }
    return rows;
}

void CrashRing::clear() {
    header()->head.store(0, std::memory_order_release);
    header()->tail.store(0, std::memory_order_release);
}

void CrashRing::append(const SampleRow& row) noexcept {
    Header* h = header();
    const std::uint64_t seq = h->head.load(std::memory_order_relaxed);
    records()[seq % capacity_] = Record{row.trial_id, row.channel_id, row.mono_ns, row.utc_ns, row.value, row.quality};
    h->head.store(seq + 1, std::memory_order_release);
}

void CrashRing::resolved(std::size_t n) noexcept {
    Header* h = header();
    h->tail.store(h->tail.load(std::memory_order_relaxed) + n, std::memory_order_release);
}

}  // namespace manikind::recorder
