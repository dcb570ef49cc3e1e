// Issue 30: "a read-only database refuses archive push, which only reads". A WAL-mode database on
// read-only media (a read-only mount, a folder this user cannot write) could not be opened even
// read-only: SQLite could not make its -shm file. Read-only commands (campaigns, log, export,
// analyze through Database::open_read_only; archive push through open_sqlite_read_only) now
// read it as the immutable file it is when nothing can write there and no -wal file exists.
// Needs a mount (root, as CI runs): run through run_if_mount.sh, skipped (77) elsewhere.
#include <catch2/catch.hpp>

#include <sqlite3.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

#include "store/database.hpp"

namespace fs = std::filesystem;

TEST_CASE("read-only media: a WAL database on a read-only mount opens read-only for every read command",
          "[storage][read-only]") {
    std::string pattern = (fs::temp_directory_path() / "manikind-ro-media-XXXXXX").string();
    REQUIRE(::mkdtemp(pattern.data()));
    const fs::path dir = pattern;
    REQUIRE(::mount("tmpfs", dir.c_str(), "tmpfs", MS_NOSUID | MS_NODEV, "size=16m,mode=0700") == 0);
    struct Unmount {
        fs::path d;
        ~Unmount() {
            ::umount2(d.c_str(), MNT_DETACH);
            std::error_code ec;
            fs::remove_all(d, ec);
        }
    } unmount{dir};
    const fs::path db_path = dir / "lab.db";
    {
        auto db = manikind::recorder::Database::open(db_path);
        REQUIRE(db.journal_mode() == "wal");
        db.create_campaign("archived", "{}");
    }  // closed: checkpointed, the -wal and -shm files gone
    REQUIRE_FALSE(fs::exists(db_path.string() + "-wal"));
    REQUIRE(::mount(nullptr, dir.c_str(), nullptr, MS_REMOUNT | MS_RDONLY | MS_NOSUID | MS_NODEV, nullptr) == 0);

    // What SQLite alone does: refuses it, even read-only.
    {
        sqlite3* raw = nullptr;
        sqlite3_open_v2(db_path.c_str(), &raw, SQLITE_OPEN_READONLY, nullptr);
        const int rc = sqlite3_exec(raw, "SELECT count(*) FROM campaigns", nullptr, nullptr, nullptr);
        sqlite3_close_v2(raw);
        CHECK((rc & 0xff) == SQLITE_CANTOPEN);
    }
    // campaigns, log, export, analyze.
    auto db = manikind::recorder::Database::open_read_only(db_path);
    const auto campaigns = db.campaigns();
    REQUIRE(campaigns.size() == 1);
    CHECK(campaigns.front().name == "archived");
    // archive push's reader.
    sqlite3* raw = nullptr;
    CHECK(manikind::recorder::open_sqlite_read_only(db_path, &raw) == SQLITE_OK);
    CHECK(sqlite3_exec(raw, "SELECT count(*) FROM campaigns", nullptr, nullptr, nullptr) == SQLITE_OK);
    sqlite3_close_v2(raw);
}
