// Benchmark (not a test): `manikin analyze` on the paper's campaign size, 45 trials x 75 min
// at 5 s x 35 zones (Text S3). Prints each figure beside its floor measured in the same run
// (end to end beside the floor on one thread and on two, as the command parses on two):
// std::from_chars over whole-file buffers, i.e. the parse with no I/O layer at all (libstdc++
// 12's from_chars for double is the fast_float algorithm, so this is the fast_float floor
// without another dependency). Then the command as a fresh process on 45 and on 450 trials,
// beside the start-up floor (`manikin --version`): it streams a folder one trial at a time, so
// its peak RSS should not grow with the number of trials.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <fmt/core.h>

#include "analysis/analyze.hpp"
#include "bench/child_run.hpp"
#include "analysis/recording.hpp"
#include "analysis/synthetic.hpp"

namespace an = manikind::analysis;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::vector<fs::path> trial_files(const fs::path& folder) {
    std::vector<fs::path> files;
    for (const auto& entry : fs::directory_iterator(folder / "trials")) files.push_back(entry.path());
    std::sort(files.begin(), files.end());
    return files;
}

// The floor: whole file into one buffer, then from_chars over every cell. Files k, k + step, ...
std::size_t floor_parse_files(const std::vector<fs::path>& files, std::size_t k, std::size_t step, double& checksum) {
    std::size_t cells = 0;
    // A local sum, stored once: the threads' checksums sit in one cache line, and a store per
    // cell made the two-thread floor slower than one thread (false sharing; 56 ms against 44).
    double sum = 0.0;
    std::vector<char> buf;
    for (std::size_t i = k; i < files.size(); i += step) {
        const fs::path& path = files[i];
        std::FILE* f = std::fopen(path.c_str(), "rb");
        if (!f) continue;
        buf.resize(fs::file_size(path));
        const std::size_t n = std::fread(buf.data(), 1, buf.size(), f);
        std::fclose(f);
        const char* p = static_cast<const char*>(std::memchr(buf.data(), '\n', n)) + 1;  // skip the header
        const char* end = buf.data() + n;
        while (p < end) {
            double v = 0.0;
            const auto r = std::from_chars(p, end, v);
            sum += v;
            ++cells;
            p = r.ptr + 1;  // past ',' or '\n'
        }
    }
    checksum += sum;
    return cells;
}

std::size_t floor_parse(const fs::path& folder, double& checksum) { return floor_parse_files(trial_files(folder), 0, 1, checksum); }

// The floor on `threads` threads, the files dealt out between them: the median of 3, in ms, the
// statistic the command's figure uses (issue 36: a best-of-3 floor against a median overstated
// the ratio). The command parses on two threads (analyze_campaign_streaming), so the two-thread
// floor is the one that truly bounds it; the one-thread floor is issue 18's yardstick.
double floor_ms(const fs::path& folder, int threads) {
    const auto files = trial_files(folder);
    std::vector<double> runs_s;
    for (int run = 0; run < 3; ++run) {
        std::vector<double> sums(static_cast<std::size_t>(threads), 0.0);
        const auto t0 = Clock::now();
        std::vector<std::thread> pool;
        for (int k = 0; k < threads; ++k)
            pool.emplace_back([&, k] {
                floor_parse_files(files, static_cast<std::size_t>(k), static_cast<std::size_t>(threads), sums[static_cast<std::size_t>(k)]);
            });
        for (auto& t : pool) t.join();
        runs_s.push_back(seconds_since(t0));
    }
    std::sort(runs_s.begin(), runs_s.end());
    return runs_s[1] * 1e3;
}

// Writes a synthetic campaign from a child process. Linux counts the memory a forked child
// shares with its parent into the child's ru_maxrss (kept across exec), so this process must
// stay small before it forks `manikin analyze`: the campaign is built elsewhere.
void generate_in_child(const fs::path& folder, int cases, int replicates) {
    std::fflush(stdout);
    const auto t0 = Clock::now();
    const pid_t pid = fork();
    if (pid == 0) {
        try {
            an::write_campaign(folder, an::make_synthetic_campaign(cases, replicates));
        } catch (const std::exception& e) {
            std::fprintf(stderr, "generating %s: %s\n", folder.c_str(), e.what());
            _exit(1);
        }
        _exit(0);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        std::fprintf(stderr, "could not generate %s\n", folder.c_str());
        std::exit(1);
    }
    std::printf("generated %d trials x 75 min at 5 s x 35 zones in %s (%.2f s)\n", cases * replicates, folder.c_str(),
                seconds_since(t0));
}

struct ChildRun {
    double wall_ms = 0.0, peak_rss_mb = 0.0;
    int exit_status = -1;
};

// One fresh `manikin <args...>`, stdout to /dev/null.
ChildRun run_child(const fs::path& manikin, const std::vector<std::string>& args) {
    const auto r = manikind::bench::run_program(manikin.string(), args);
    return {r.wall_s * 1e3, r.peak_mb, r.status};
}

// The median wall time of `runs` fresh processes, and the largest peak RSS among them.
ChildRun median_child(const fs::path& manikin, const std::vector<std::string>& args, int runs) {
    std::vector<double> walls;
    ChildRun out;
    for (int i = 0; i < runs; ++i) {
        const auto r = run_child(manikin, args);
        walls.push_back(r.wall_ms);
        out.peak_rss_mb = std::max(out.peak_rss_mb, r.peak_rss_mb);
        out.exit_status = r.exit_status;
    }
    std::sort(walls.begin(), walls.end());
    out.wall_ms = walls[walls.size() / 2];
    return out;
}

// `manikin analyze <folder> --json` as a user runs it, in fresh processes (median of 3), then
// the parse floors on the same files (measured after, so this process is still small when it
// forks); returns the lines to print.
std::string run_manikin(const fs::path& manikin, const fs::path& folder, int trials) {
    const auto r = median_child(manikin, {"analyze", folder.string(), "--json"}, 3);
    const double one = floor_ms(folder, 1), two = floor_ms(folder, 2);
    return fmt::format("manikin analyze --json (fresh process, median of 3), {:3} trials: {:7.1f} ms wall, peak RSS {:.1f} MB, exit {}\n"
                       "    floor on the same files: {:6.1f} ms on one thread ({:.2f}x), {:6.1f} ms on two ({:.2f}x)\n",
                       trials, r.wall_ms, r.peak_rss_mb, r.exit_status, one, r.wall_ms / one, two, r.wall_ms / two);
}

}  // namespace

int main(int argc, char** argv) {
    const int cases = 15, large_cases = 150, replicates = 3;
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-bench-analyze-{}", ::getpid());
    const fs::path large = dir.string() + "-large";
    fs::remove_all(dir);
    fs::remove_all(large);
    generate_in_child(dir, cases, replicates);

    // End to end as a user runs it: the manikin binary beside this one, on 45 and 450 trials.
    // Run first, while this process is small (see generate_in_child); printed last.
    std::string fresh;
    const fs::path manikin = fs::path(argv[0]).parent_path() / "manikin";
    if (argc > 0 && fs::exists(manikin)) {
        // The start-up floor: loading the binary and its libraries, parsing no data.
        const auto startup = median_child(manikin, {"--version"}, 5);
        fresh += fmt::format("floor: manikin --version (fresh process, median of 5): {:.1f} ms wall, peak RSS {:.1f} MB\n",
                             startup.wall_ms, startup.peak_rss_mb);
        fresh += run_manikin(manikin, dir, cases * replicates);
        generate_in_child(large, large_cases, replicates);
        fresh += run_manikin(manikin, large, large_cases * replicates);
        fs::remove_all(large);
    } else {
        fresh = "(build the manikin target to time the command end to end)\n";
    }

    std::uintmax_t bytes = 0;
    for (const auto& e : fs::directory_iterator(dir / "trials")) bytes += fs::file_size(e.path());

    const int repeats = 5;
    double best_floor = 1e9, best_parse = 1e9, best_analyze = 1e9, best_streaming = 1e9, checksum = 0.0;
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
        t0 = Clock::now();
        const std::string streamed = an::to_json(an::analyze_campaign_streaming(dir)).dump();
        best_streaming = std::min(best_streaming, seconds_since(t0));
        if (streamed != json) std::printf("MISMATCH: the streaming result differs from the in-memory one\n");
    }
    rusage self{};
    getrusage(RUSAGE_SELF, &self);
    std::printf("data: %.1f MB, %zu cells, %zu cases analysed (checksum %.3g)\n", static_cast<double>(bytes) / 1e6, cells,
                result.cases.size(), checksum);
    std::printf("parse    %7.1f ms  (%.0f MB/s)   floor (whole-file buffer + from_chars) %7.1f ms  ratio %.2f\n",
                best_parse * 1e3, static_cast<double>(bytes) / 1e6 / best_parse, best_floor * 1e3, best_parse / best_floor);
    std::printf("analyze  %7.1f ms  (steady state, GUM, JSON)\n", best_analyze * 1e3);
    std::printf("total    %7.1f ms  best of %d in-process; peak RSS of this process %.1f MB\n",
                (best_parse + best_analyze) * 1e3, repeats, static_cast<double>(self.ru_maxrss) / 1024.0);
    std::printf("stream   %7.1f ms  two trials parsed at once, one summarised, + JSON, as `manikin analyze <folder>` does\n",
                best_streaming * 1e3);
    std::fputs(fresh.c_str(), stdout);
    fs::remove_all(dir);
    return 0;
}
