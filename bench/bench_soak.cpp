// Soak (issue 17; a benchmark, not a test): the whole daemon on the simulated lab for 7 days of
// virtual time, campaigns back to back, a device fault every 3 hours (each device in turn:
// silences, Modbus exceptions, dropped connections, garbage and bad checksums on the serial
// lines, CAN error frames and bus-off; a silent manikin or chamber trips the watchdog, which
// aborts the campaign, and the next one starts). Every virtual hour it prints resident memory,
// open file descriptors and the database's size; at the end, what the later days add per day.
// Flat means: memory and fds do not grow once the daemon has seen every path (after day 1), and
// the database grows by the same amount each day (the data, nothing else).
//   bench_soak [days]     default 7
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include "daemon/lab_daemon.hpp"

namespace fs = std::filesystem;

namespace {

double resident_mb() {
    std::ifstream statm("/proc/self/statm");
    long pages_total = 0, pages_resident = 0;
    statm >> pages_total >> pages_resident;
    return static_cast<double>(pages_resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / 1048576.0;
}

int open_fds() {
    int n = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator("/proc/self/fd")) ++n;
    return n - 1;  // the iterator's own
}

double file_mb(const fs::path& p) {
    std::error_code ec;
    const auto size = fs::file_size(p, ec);
    return ec ? 0.0 : static_cast<double>(size) / 1048576.0;
}

// One fault every 3 h for `days`, 2 to 10 min long, cycling through every device and kind.
std::vector<std::string> fault_schedule(int days) {
    const std::vector<std::string> kinds = {
        "datalogger:silent", "windsonic:garbage",  "chamber:exception",   "csat3b:bad_checksum", "manikin:error_frames",
        "datalogger:drop",   "windsonic:silent",   "chamber:silent",      "csat3b:silent",       "manikin:silent",
        "datalogger:exception", "windsonic:bad_checksum", "chamber:drop", "csat3b:garbage",      "manikin:bus_off"};
    std::vector<std::string> out;
    int i = 0;
    for (double t = 3600.0; t < days * 86400.0; t += 3 * 3600.0, ++i) {
        const double length_s = 120.0 + 60.0 * (i % 9);
        out.push_back(fmt::format("{}@{:.0f}-{:.0f}", kinds[static_cast<std::size_t>(i) % kinds.size()], t, t + length_s));
    }
    return out;
}

manikind::CampaignPlan soak_plan(int n) {
    manikind::CampaignPlan p;
    p.name = fmt::format("soak-{:03d}", n);
    p.replicates = 3;
    p.trial_duration_s = 75 * 60.0;
    p.cases.push_back({1, 35.0, 27.0, 35.0, false, 0.0, std::nullopt, std::nullopt, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});
    p.cases.push_back({2, 35.0, 27.0, 35.0, true, 300.0, std::nullopt, std::nullopt, "", "", std::nullopt, std::nullopt, {}, std::nullopt, {}});  // Table S3's dry and wet skin at 35 °C
    return p;
}

// Least-squares slope of y over x.
double slope(const std::vector<double>& x, const std::vector<double>& y) {
    const double n = static_cast<double>(x.size());
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (std::size_t i = 0; i < x.size(); ++i) sx += x[i], sy += y[i], sxx += x[i] * x[i], sxy += x[i] * y[i];
    const double d = n * sxx - sx * sx;
    return d != 0 ? (n * sxy - sx * sy) / d : 0.0;
}

}  // namespace

int main(int argc, char** argv) {
    const int days = argc > 1 ? std::atoi(argv[1]) : 7;
    if (days < 2 || days > 60) {
        std::fprintf(stderr, "usage: bench_soak [days]   (2..60, default 7)\n");
        return 2;
    }
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-soak-{}", ::getpid());
    fs::create_directories(dir);
    auto config = manikind::config::default_config();
    config.database = dir / "soak.db";
    config.simulation.runtime_dir = (dir / "sim").string();
    config.simulation.faults = fault_schedule(days);
    spdlog::set_level(spdlog::level::off);  // the alarms are counted in the table instead
    const fs::path db = config.database;

    std::printf("soak: %d days of virtual time, %zu device faults (one every 3 h), campaigns of 2 cases x 3 "
                "replicates back to back\n",
                days, config.simulation.faults.size());
    std::printf("%5s %9s %7s %5s %9s %9s %7s %8s %7s\n", "hour", "wall_s", "rss_MB", "fds", "db_MB", "wal_MB",
                "trials", "campaign", "alarms");
    std::vector<double> hours, rss, fds, db_mb;
    const auto wall0 = std::chrono::steady_clock::now();
    int campaigns = 0;
    {
        manikind::LabDaemon daemon(manikind::DaemonOptions{config, true, 1.0});
        const double step_s = config.simulation.step_s;
        int trials_done = 0;
        for (int hour = 1; hour <= days * 24; ++hour) {
            for (double t = 0; t < 3600.0; t += step_s) {
                if (!daemon.campaign_active()) {
                    const auto why = daemon.start_campaign(soak_plan(++campaigns));
                    if (!why.empty()) std::fprintf(stderr, "soak: campaign %d refused: %s\n", campaigns, why.c_str());
                }
                daemon.step_virtual(step_s);
            }
            daemon.flush_recorder();
            const auto status = daemon.status_json();
            trials_done = 0;
            for (const auto& c : daemon.db().campaigns())
                for (const auto& tr : daemon.db().trials(c.id)) trials_done += tr.state == "done";
            const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
            hours.push_back(hour);
            rss.push_back(resident_mb());
            fds.push_back(open_fds());
            db_mb.push_back(file_mb(db) + file_mb(fs::path(db.string() + "-wal")));
            std::printf("%5d %9.1f %7.1f %5.0f %9.1f %9.1f %7d %8d %7zu\n", hour, wall_s, rss.back(), fds.back(),
                        file_mb(db), file_mb(fs::path(db.string() + "-wal")), trials_done, campaigns,
                        daemon.alarms_json().size());
            std::fflush(stdout);
        }
        const auto rs = daemon.status_json()["recorder"];
        std::printf("recorder: %s\n", rs.dump().c_str());
    }

    // Day 1 warms up (every channel, every fault path, SQLite's page cache); judge the rest.
    std::vector<double> h, r, f, d;
    for (std::size_t i = 0; i < hours.size(); ++i)
        if (hours[i] > 24) h.push_back(hours[i]), r.push_back(rss[i]), f.push_back(fds[i]), d.push_back(db_mb[i]);
    const double rss_per_day = slope(h, r) * 24;
    const auto [fd_min, fd_max] = std::minmax_element(f.begin(), f.end());
    // The database's growth per day, day by day after the first.
    std::printf("database growth per day:");
    std::vector<double> per_day;
    for (int day = 2; day <= days; ++day) {
        per_day.push_back(db_mb[static_cast<std::size_t>(day * 24 - 1)] - db_mb[static_cast<std::size_t>(day * 24 - 25)]);
        std::printf(" %.1f", per_day.back());
    }
    std::printf(" MB\n");
    // Resident memory day by day: the plateau is the point (a leak climbs every day).
    std::printf("resident memory by day, mean (max):");
    for (int day = 1; day <= days; ++day) {
        double sum = 0, top = 0;
        for (int hr = (day - 1) * 24; hr < day * 24; ++hr) sum += rss[static_cast<std::size_t>(hr)], top = std::max(top, rss[static_cast<std::size_t>(hr)]);
        std::printf(" %.1f (%.1f)", sum / 24, top);
    }
    std::printf(" MB\n");
    const auto [day_min, day_max] = std::minmax_element(per_day.begin(), per_day.end());
    std::printf("after day 1: resident memory %+.2f MB/day (least squares; %.1f MB at the end), open fds %.0f..%.0f, "
                "database +%.1f..%.1f MB/day\n",
                rss_per_day, rss.back(), *fd_min, *fd_max, *day_min, *day_max);
    std::printf("campaigns started: %d; wall time %.0f s for %d virtual days\n", campaigns,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count(), days);
    std::error_code ec;
    fs::remove_all(dir, ec);
    return 0;
}
