// The output guard (issue 60): a database is its main file, -wal, -shm and -journal, recognised
// by name as well as by header, through symbolic links; refused --force or not.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "base/user_error.hpp"
#include "store/export_target.hpp"

namespace fs = std::filesystem;
using manikind::ExportShape;
using manikind::ExportTarget;
using manikind::refuse_protected_output;
using manikind::UserError;

namespace {

struct Folder {
    fs::path path = fs::temp_directory_path() / ("manikind-guard-store-" + std::to_string(::getpid()));
    Folder() {
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~Folder() { fs::remove_all(path); }
};

void write_bytes(const fs::path& p, const std::string& bytes) { std::ofstream(p, std::ios::binary) << bytes; }

// The refusal's message; empty when `out` is allowed.
std::string refusal(const fs::path& out, const std::vector<fs::path>& inputs = {}) {
    try {
        refuse_protected_output(out, inputs);
    } catch (const UserError& e) {
        CHECK(e.code() == "output_refused");
        return e.what();
    }
    return {};
}

}  // namespace

TEST_CASE("output guard: a database's companions are refused by name even empty or when missing", "[store][export][hostile]") {
    Folder dir;
    write_bytes(dir.path / "lab.db", std::string("SQLite format 3\0", 16) + std::string(84, '\0'));
    write_bytes(dir.path / "lab.db-shm", "");
    CHECK(refusal(dir.path / "lab.db").find("is an SQLite database") != std::string::npos);
    CHECK(refusal(dir.path / "lab.db-shm").find("shared-memory index of the database") != std::string::npos);
    // Not there yet: a -wal or -journal beside a database is still its companion.
    CHECK(refusal(dir.path / "lab.db-wal").find("write-ahead log of the database") != std::string::npos);
    CHECK(refusal(dir.path / "lab.db-journal").find("rollback journal of the database") != std::string::npos);
    CHECK_FALSE(fs::exists(dir.path / "lab.db-wal"));
    // Beside no database, the name alone means nothing.
    CHECK(refusal(dir.path / "notes-wal").empty());
    CHECK(refusal(dir.path / "report.html").empty());
}

TEST_CASE("output guard: a write-ahead log or rollback journal is refused by its header under any name",
          "[store][export][hostile]") {
    Folder dir;
    write_bytes(dir.path / "copy-of-wal.bin", std::string("\x37\x7f\x06\x82", 4) + std::string(28, '\0'));
    write_bytes(dir.path / "wal-big-endian-checksums.bin", std::string("\x37\x7f\x06\x83", 4) + std::string(28, '\0'));
    write_bytes(dir.path / "journal.bin", std::string("\xd9\xd5\x05\xf9\x20\xa1\x63\xd7", 8) + std::string(20, '\0'));
    write_bytes(dir.path / "text.txt", "\x37\x7f");
    CHECK(refusal(dir.path / "copy-of-wal.bin").find("write-ahead log") != std::string::npos);
    CHECK(refusal(dir.path / "wal-big-endian-checksums.bin").find("write-ahead log") != std::string::npos);
    CHECK(refusal(dir.path / "journal.bin").find("rollback journal") != std::string::npos);
    CHECK(refusal(dir.path / "text.txt").empty());
    // ExportTarget applies the same rule with --force.
    CHECK_THROWS_AS(ExportTarget(dir.path / "copy-of-wal.bin", ExportShape::file, true, {}), UserError);
    CHECK_THROWS_AS(ExportTarget(dir.path / "journal.bin", ExportShape::file, true, {}), UserError);
}

TEST_CASE("output guard: an input named through a link protects the real database's companions and a folder everything in it",
          "[store][export][hostile]") {
    Folder dir;
    fs::create_directories(dir.path / "real");
    // Named so that only the input rule can know it: no database beside it by name.
    write_bytes(dir.path / "real" / "lab.db", "not yet a database");
    fs::create_symlink(dir.path / "real" / "lab.db", dir.path / "link.db");
    fs::create_symlink(dir.path / "real", dir.path / "linked-folder");
    const std::string via_link = refusal(dir.path / "linked-folder" / "lab.db-shm", {dir.path / "link.db"});
    CHECK(via_link.find("which this command reads") != std::string::npos);
    CHECK(refusal(dir.path / "real" / "lab.db", {dir.path / "link.db"}).find("which this command reads") != std::string::npos);
    // A campaign folder read: everything in it, new or not, and through a link to it.
    fs::create_directories(dir.path / "campaign" / "trials");
    write_bytes(dir.path / "campaign" / "campaign.json", "{}");
    fs::create_symlink(dir.path / "campaign", dir.path / "campaign-link");
    for (const auto& out : {dir.path / "campaign" / "campaign.json", dir.path / "campaign" / "trials" / "c01-r1.csv",
                            dir.path / "campaign" / "report.html"})
        CHECK(refusal(out, {dir.path / "campaign-link"}).find("inside the campaign folder") != std::string::npos);
    CHECK(refusal(dir.path / "campaign-report.html", {dir.path / "campaign"}).empty());
}
