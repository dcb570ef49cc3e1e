#pragma once
// What the archive tests compare: per trial, the rows, the sum of values and the sum of monotonic
// stamps, in the recorder's SQLite file and in the PostgreSQL archive. Equal counts under the
// archive's primary key mean every sample arrived exactly once.
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

#include <catch2/catch.hpp>

#include "archive/pg.hpp"
#include "store/database.hpp"

namespace manikind::test {

struct TrialSums {
    std::int64_t rows = 0;
    double value_sum = 0.0;  // NULLs (NaN) left out, as SQL's sum does
    std::int64_t mono_ns_sum = 0;  // of mono_ns mod kStampModulus: a plain sum overflows 64 bits on a long trial
};

constexpr std::int64_t kStampModulus = 1'000'000'007;

inline std::map<std::string, TrialSums> sqlite_sums(const std::filesystem::path& path) {
    auto db = recorder::Database::open(path);
    std::map<std::string, TrialSums> sums;
    for (const auto& campaign : db.campaigns()) {
        for (const auto& trial : db.trials(campaign.id)) {
            auto& s = sums[trial.uuid];
            db.for_each_trial_sample(trial.id, [&](const recorder::SampleRow& row) {
                ++s.rows;
                if (!std::isnan(row.value)) s.value_sum += row.value;
                s.mono_ns_sum += row.mono_ns % kStampModulus;
            });
        }
    }
    return sums;
}

// `lab_id` empty: every lab's trials.
inline std::map<std::string, TrialSums> archive_sums(const std::string& conninfo, const std::string& lab_id = {}) {
    auto pg = archive::PgConnection::connect(conninfo);
    auto r = pg.exec("SELECT trial_uuid, count(*), coalesce(sum(value), 0), sum(mono_ns % 1000000007) FROM samples WHERE $1 = ''"
                     " OR trial_uuid IN (SELECT trial_uuid FROM trials WHERE lab_id = $1) GROUP BY trial_uuid",
                     {lab_id});
    std::map<std::string, TrialSums> sums;
    for (int i = 0; i < r.rows(); ++i)
        sums[r.text(i, 0)] = TrialSums{r.int64(i, 1), std::stod(r.text(i, 2)), std::stoll(r.text(i, 3))};
    return sums;
}

// Trials with no samples yet are absent from the archive's GROUP BY: compared only where the
// SQLite file has rows.
inline void check_archive_equals_sqlite(const std::filesystem::path& db, const std::string& conninfo,
                                        const std::string& lab_id = {}) {
    const auto want = sqlite_sums(db);
    const auto got = archive_sums(conninfo, lab_id);
    std::size_t with_rows = 0;
    for (const auto& [uuid, w] : want) {
        if (w.rows == 0) continue;
        ++with_rows;
        INFO("trial " << uuid);
        REQUIRE(got.count(uuid) == 1);
        const auto& g = got.at(uuid);
        CHECK(g.rows == w.rows);
        CHECK(g.mono_ns_sum == w.mono_ns_sum);
        CHECK(g.value_sum == Approx(w.value_sum).epsilon(1e-9));  // summed in another order; one row is ~1e-6
    }
    CHECK(got.size() == with_rows);
}

#ifdef MANIKIND_BIN_DIR
struct CliResult {
    int status = -1;
    std::string out;
};

// build/bin/manikin as a user runs it; stdout captured, stderr left to the test's log.
inline CliResult run_manikin(const std::string& args) {
    CliResult r;
    const std::string cmd = std::string(MANIKIND_BIN_DIR) + "/manikin " + args;
    FILE* pipe = popen(cmd.c_str(), "r");
    if (!pipe) return r;
    char buffer[4096];
    for (std::size_t n; (n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0;) r.out.append(buffer, n);
    const int status = pclose(pipe);
    r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}
#endif

}  // namespace manikind::test
