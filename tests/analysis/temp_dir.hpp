#pragma once
// A fresh folder under the system temp dir, removed when the test ends (shared by the
// tests/analysis files that write campaigns).
#include <atomic>
#include <filesystem>
#include <string>
#include <unistd.h>

namespace manikind::test {

struct TempDir {
    std::filesystem::path path;
    TempDir() {
        static std::atomic<int> counter{0};
        path = std::filesystem::temp_directory_path() /
               ("manikind-test-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        std::filesystem::remove_all(path);
    }
    ~TempDir() { std::filesystem::remove_all(path); }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
};

}  // namespace manikind::test
