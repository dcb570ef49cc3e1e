#pragma once
// Where an export writes (issue 30, docs/cli.md "export"): an output can never destroy an
// input. Before anything is read, the path is checked; the export is written whole under a new
// hidden name beside it and renamed into place only when complete; on any error that name is
// removed, so a failed export leaves nothing behind.
//
// Refused always, --force or not: whatever refuse_protected_output refuses (a database and its
// companions, an input), a symbolic link, a device, FIFO or socket, a folder where a file is
// wanted and a file where a folder is wanted, and a non-empty folder that is not an earlier
// export (a campaign.json and trials/ only). Refused unless --force: an existing file or export
// folder.
#include <filesystem>
#include <string>
#include <vector>

namespace manikind {

enum class ExportShape { file, folder };

// The rule every file a command writes obeys, --force or not (issue 60): throws UserError
// "output_refused" naming the path, what it is and why, when `out` (symbolic links resolved) is
//   - an SQLite database, write-ahead log or rollback journal by its header;
//   - named <db>-wal, -shm or -journal where <db> exists: any database's companion, even an empty
//     -shm or the -wal a crashed daemon left (its committed samples live only there);
//   - one of `inputs` or, for an input file, its -wal, -shm or -journal (inputs are resolved too,
//     so a database named through a link protects its real companions);
//   - inside an input that is a folder (a campaign folder read: everything in it).
// For writers that open the path themselves (no ExportTarget): call it before reading.
void refuse_protected_output(const std::filesystem::path& out, const std::vector<std::filesystem::path>& inputs);

class ExportTarget {
public:
    // Checks `out` (UserError, exit 2, naming the path and why); `inputs` are the databases and
    // campaign folders read.
    ExportTarget(std::filesystem::path out, ExportShape shape, bool force,
                 const std::vector<std::filesystem::path>& inputs);
    ~ExportTarget();  // removes the staging unless committed: nothing half-written is left
    ExportTarget(const ExportTarget&) = delete;
    ExportTarget& operator=(const ExportTarget&) = delete;

    // The name to write the whole export to (a file or a folder), beside the final one.
    const std::filesystem::path& staging() const { return staging_; }
    // Flushes the staging to the disk and renames it to the final name (the replaced export, if
    // --force allowed one, goes only once the new one is in place).
    void commit();

private:
    std::filesystem::path out_, staging_;
    ExportShape shape_;
    bool replace_ = false;
    bool committed_ = false;
};

}  // namespace manikind
