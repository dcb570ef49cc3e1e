// Benchmark (not a test): `manikin analyze` on the paper's campaign size, 45 trials x 75 min
// at 5 s x 35 zones (Text S3). Prints each figure beside its floor measured in the same run:
// std::from_chars over whole-file buffers, i.e. the parse with no I/O layer at all.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "analysis/analyze.hpp"
#include "analysis/recording.hpp"
#include "analysis/synthetic.hpp"

namespace an = manikind::analysis;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// The floor: whole file into one buffer, then from_chars over every cell.
std::size_t floor_parse(const fs::path& folder, double& checksum) {
    std::size_t cells = 0;
    std::vector<char> buf;
    for (const auto& entry : fs::directory_iterator(folder / "trials")) {
        std::FILE* f = std::fopen(entry.path().c_str(), "rb");
        if (!f) continue;
        buf.resize(fs::file_size(entry.path()));
        const std::size_t n = std::fread(buf.data(), 1, buf.size(), f);
        std::fclose(f);
        const char* p = static_cast<const char*>(std::memchr(buf.data(), '\n', n)) + 1;  // skip the header
        const char* end = buf.data() + n;
        while (p < end) {
            double v = 0.0;
            const auto r = std::from_chars(p, end, v);
            checksum += v;
            ++cells;
            p = r.ptr + 1;  // past ',' or '\n'
        }
    }
    return cells;
}

}  // namespace

int main(int argc, char** argv) {
    const int cases = 15, replicates = 3;
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-bench-analyze-{}", ::getpid());
    fs::remove_all(dir);
    {
        const auto t0 = Clock::now();
        an::write_campaign(dir, an::make_synthetic_campaign(cases, replicates));
        std::printf("generated %d trials x 75 min at 5 s x 35 zones in %s (%.2f s)\n", cases * replicates,
                    dir.c_str(), seconds_since(t0));
    }
    std::uintmax_t bytes = 0;
    for (const auto& e : fs::directory_iterator(dir / "trials")) bytes += fs::file_size(e.path());

    const int repeats = 5;
    double best_floor = 1e9, best_parse = 1e9, best_analyze = 1e9, checksum = 0.0;
    std::size_t cells = 0;
    an::CampaignResult result;
    for (int i = 0; i < repeats; ++i) {
        auto t0 = Clock::now();
        cells = floor_parse(dir, checksum);
        best_floor = std::min(best_floor, seconds_since(t0));
        t0 = Clock::now();
        const auto campaign = an::read_campaign(dir);
        best_parse = std::min(best_parse, seconds_since(t0));
        t0 = Clock::now();
        result = an::analyze_campaign(campaign);
        const std::string json = an::to_json(result).dump();
        best_analyze = std::min(best_analyze, seconds_since(t0));
        checksum += static_cast<double>(json.size());
    }
    rusage self{};
    getrusage(RUSAGE_SELF, &self);
    std::printf("data: %.1f MB, %zu cells, %zu cases analysed (checksum %.3g)\n", static_cast<double>(bytes) / 1e6, cells,
                result.cases.size(), checksum);
    std::printf("parse    %7.1f ms  (%.0f MB/s)   floor (whole-file buffer + from_chars) %7.1f ms  ratio %.2f\n",
                best_parse * 1e3, static_cast<double>(bytes) / 1e6 / best_parse, best_floor * 1e3, best_parse / best_floor);
    std::printf("analyze  %7.1f ms  (steady state, GUM, JSON)\n", best_analyze * 1e3);
    std::printf("total    %7.1f ms  best of %d in-process; peak RSS of this process %.1f MB (includes the generator)\n",
                (best_parse + best_analyze) * 1e3, repeats, static_cast<double>(self.ru_maxrss) / 1024.0);

    // End to end as a user runs it: the manikin binary beside this one.
    const fs::path manikin = fs::path(argv[0]).parent_path() / "manikin";
    if (argc > 0 && fs::exists(manikin)) {
        std::fflush(stdout);  // or the child's freopen would print our buffer twice
        const auto t0 = Clock::now();
        const pid_t pid = fork();
        if (pid == 0) {
            std::freopen("/dev/null", "w", stdout);
            execl(manikin.c_str(), "manikin", "analyze", dir.c_str(), "--json", static_cast<char*>(nullptr));
            _exit(127);
        }
        int status = 0;
        rusage child{};
        wait4(pid, &status, 0, &child);
        std::printf("manikin analyze --json (fresh process): %.1f ms wall, peak RSS %.1f MB, exit %d\n",
                    seconds_since(t0) * 1e3, static_cast<double>(child.ru_maxrss) / 1024.0,
                    WIFEXITED(status) ? WEXITSTATUS(status) : -1);
    } else {
        std::printf("(build the manikin target to time the command end to end)\n");
    }
    fs::remove_all(dir);
    return 0;
}
