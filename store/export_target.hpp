#pragma once
// Where an export writes (issue 30, docs/cli.md "export"): an output can never destroy an
// input. Before anything is read, the path is checked; the export is written whole under a new
// hidden name beside it and renamed into place only when complete; on any error that name is
// removed, so a failed export leaves nothing behind.
//
// Refused always, --force or not: a symbolic link, a device, FIFO or socket, any SQLite
// database (its first 16 bytes), the database the export reads or its -wal/-shm/-journal, a
// folder where a file is wanted and a file where a folder is wanted, and a non-empty folder that
// is not an earlier export (a campaign.json and trials/ only). Refused unless --force: an
// existing file or export folder.
#include <filesystem>
#include <string>
#include <vector>

namespace manikind {

enum class ExportShape { file, folder };

class ExportTarget {
public:
    // Checks `out` (UserError, exit 2, naming the path and why); `inputs` are the databases read.
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
