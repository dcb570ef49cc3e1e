#pragma once
// A file system that fails on demand: an SQLite VFS wrapping the default one, made the default
// for as long as it lives, so that every connection the code under test opens goes through it.
// While armed, every write, truncate and sync of the database, its WAL or its journal fails with
// the chosen code (SQLITE_FULL: a full disk; SQLITE_IOERR_WRITE: an unplugged disk), as the
// kernel would make them fail; reads, locks and shared memory work.
#include <sqlite3.h>

#include <atomic>
#include <mutex>
#include <stdexcept>

namespace manikind::test {

class FaultyVfs {
public:
    FaultyVfs() {
        real_ = sqlite3_vfs_find(nullptr);
        if (!real_) throw std::runtime_error("no default SQLite VFS");
        vfs_ = *real_;
        vfs_.zName = "manikind-faulty";
        vfs_.szOsFile = static_cast<int>(sizeof(File)) + real_->szOsFile;
        vfs_.pAppData = this;
        vfs_.xOpen = &FaultyVfs::open;
        if (sqlite3_vfs_register(&vfs_, 1) != SQLITE_OK) throw std::runtime_error("cannot register the faulty VFS");
        self() = this;
    }
    ~FaultyVfs() {
        sqlite3_vfs_unregister(&vfs_);
        sqlite3_vfs_register(real_, 1);
        self() = nullptr;
    }
    FaultyVfs(const FaultyVfs&) = delete;
    FaultyVfs& operator=(const FaultyVfs&) = delete;

    void arm(int sqlite_code) { failing_ = sqlite_code; }
    void disarm() { failing_ = SQLITE_OK; }
    int failures() const { return failures_; }  // writes refused while armed

private:
    struct File {
        sqlite3_file base;
        sqlite3_file* real;  // the wrapped file, in the same allocation, just after this struct
    };

    static FaultyVfs*& self() {
        static FaultyVfs* instance = nullptr;
        return instance;
    }
    static sqlite3_file* real_of(sqlite3_file* f) { return reinterpret_cast<File*>(f)->real; }
    int fault() {
        const int code = failing_.load();
        if (code != SQLITE_OK) ++failures_;
        return code;
    }

    static int open(sqlite3_vfs* vfs, const char* name, sqlite3_file* file, int flags, int* out_flags) {
        auto* me = static_cast<FaultyVfs*>(vfs->pAppData);
        auto* f = reinterpret_cast<File*>(file);
        f->real = reinterpret_cast<sqlite3_file*>(f + 1);
        const int rc = me->real_->xOpen(me->real_, name, f->real, flags, out_flags);
        if (rc != SQLITE_OK || f->real->pMethods == nullptr) {
            f->base.pMethods = nullptr;
            return rc;
        }
        std::call_once(me->methods_made_, [&] { me->make_methods(*f->real->pMethods); });
        f->base.pMethods = &me->methods_;
        return SQLITE_OK;
    }

    void make_methods(const sqlite3_io_methods& real) {
        auto* me = this;
        me->methods_ = real;
        me->methods_.xClose = [](sqlite3_file* x) {
            const int r = real_of(x)->pMethods->xClose(real_of(x));
            x->pMethods = nullptr;
            return r;
        };
        me->methods_.xRead = [](sqlite3_file* x, void* p, int n, sqlite3_int64 o) { return real_of(x)->pMethods->xRead(real_of(x), p, n, o); };
        me->methods_.xWrite = [](sqlite3_file* x, const void* p, int n, sqlite3_int64 o) {
            if (const int c = self()->fault(); c != SQLITE_OK) return c;
            return real_of(x)->pMethods->xWrite(real_of(x), p, n, o);
        };
        me->methods_.xTruncate = [](sqlite3_file* x, sqlite3_int64 size) {
            if (const int c = self()->fault(); c != SQLITE_OK) return c == SQLITE_FULL ? SQLITE_FULL : SQLITE_IOERR_TRUNCATE;
            return real_of(x)->pMethods->xTruncate(real_of(x), size);
        };
        me->methods_.xSync = [](sqlite3_file* x, int flags) {
            if (const int c = self()->fault(); c != SQLITE_OK) return c == SQLITE_FULL ? SQLITE_FULL : SQLITE_IOERR_FSYNC;
            return real_of(x)->pMethods->xSync(real_of(x), flags);
        };
        me->methods_.xFileSize = [](sqlite3_file* x, sqlite3_int64* s) { return real_of(x)->pMethods->xFileSize(real_of(x), s); };
        me->methods_.xLock = [](sqlite3_file* x, int l) { return real_of(x)->pMethods->xLock(real_of(x), l); };
        me->methods_.xUnlock = [](sqlite3_file* x, int l) { return real_of(x)->pMethods->xUnlock(real_of(x), l); };
        me->methods_.xCheckReservedLock = [](sqlite3_file* x, int* r) { return real_of(x)->pMethods->xCheckReservedLock(real_of(x), r); };
        me->methods_.xFileControl = [](sqlite3_file* x, int op, void* a) { return real_of(x)->pMethods->xFileControl(real_of(x), op, a); };
        me->methods_.xSectorSize = [](sqlite3_file* x) { return real_of(x)->pMethods->xSectorSize(real_of(x)); };
        me->methods_.xDeviceCharacteristics = [](sqlite3_file* x) { return real_of(x)->pMethods->xDeviceCharacteristics(real_of(x)); };
        if (me->methods_.iVersion >= 2) {
            me->methods_.xShmMap = [](sqlite3_file* x, int pg, int sz, int ext, void volatile** p) {
                return real_of(x)->pMethods->xShmMap(real_of(x), pg, sz, ext, p);
            };
            me->methods_.xShmLock = [](sqlite3_file* x, int o, int n, int fl) { return real_of(x)->pMethods->xShmLock(real_of(x), o, n, fl); };
            me->methods_.xShmBarrier = [](sqlite3_file* x) { real_of(x)->pMethods->xShmBarrier(real_of(x)); };
            me->methods_.xShmUnmap = [](sqlite3_file* x, int del) { return real_of(x)->pMethods->xShmUnmap(real_of(x), del); };
        }
        if (me->methods_.iVersion >= 3) {
            // No memory-mapped I/O: every page goes through xRead/xWrite, where the faults are.
            me->methods_.xFetch = [](sqlite3_file*, sqlite3_int64, int, void** p) {
                *p = nullptr;
                return SQLITE_OK;
            };
            me->methods_.xUnfetch = [](sqlite3_file*, sqlite3_int64, void*) { return SQLITE_OK; };
        }
    }

    sqlite3_vfs* real_ = nullptr;
    sqlite3_vfs vfs_{};
    std::once_flag methods_made_;
    sqlite3_io_methods methods_{};  // every file the default VFS opens has the same methods (unix)
    std::atomic<int> failing_{SQLITE_OK};
    std::atomic<int> failures_{0};
};

}  // namespace manikind::test
