#pragma once
// What the archive tests compare: per trial, the rows, the sum of values and the sum of monotonic
// stamps, in the recorder's SQLite file and in the PostgreSQL archive. Equal counts under the
// archive's primary key mean every sample arrived exactly once.
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

#include <catch2/catch.hpp>

#include "archive/pg.hpp"
#include "daemon/core/recorder/database.hpp"

namespace manikind::test {

struct TrialSums {
    std::int64_t rows = 0;
    double value_sum = 0.0;  // NULLs (NaN) left out, as SQL's sum does
    std::int64_t mono_ns_sum = 0;
};

inline std::map<std::string, TrialSums> sqlite_sums(const std::filesystem::path& path) {
    auto db = recorder::Database::open(path);
    std::map<std::string, TrialSums> sums;
    for (const auto& campaign : db.campaigns()) {
        for (const auto& trial : db.trials(campaign.id)) {
            auto& s = sums[trial.uuid];
            db.for_each_trial_sample(trial.id, [&](const recorder::SampleRow& row) {
                ++s.rows;
                if (!std::isnan(row.value)) s.value_sum += row.value;
                s.mono_ns_sum += row.mono_ns;
            });
        }
    }
    return sums;
}

inline std::map<std::string, TrialSums> archive_sums(const std::string& conninfo) {
    auto pg = archive::PgConnection::connect(conninfo);
    auto r = pg.exec("SELECT trial_uuid, count(*), coalesce(sum(value), 0), sum(mono_ns) FROM samples GROUP BY trial_uuid");
    std::map<std::string, TrialSums> sums;
    for (int i = 0; i < r.rows(); ++i)
        sums[r.text(i, 0)] = TrialSums{r.int64(i, 1), std::stod(r.text(i, 2)), std::stoll(r.text(i, 3))};
    return sums;
}

// Trials with no samples yet are absent from the archive's GROUP BY: compared only where the
// SQLite file has rows.
inline void check_archive_equals_sqlite(const std::filesystem::path& db, const std::string& conninfo) {
    const auto want = sqlite_sums(db);
    const auto got = archive_sums(conninfo);
    std::size_t with_rows = 0;
    for (const auto& [uuid, w] : want) {
        if (w.rows == 0) continue;
        ++with_rows;
        INFO("trial " << uuid);
        REQUIRE(got.count(uuid) == 1);
        const auto& g = got.at(uuid);
        CHECK(g.rows == w.rows);
        CHECK(g.mono_ns_sum == w.mono_ns_sum);
        CHECK(g.value_sum == Approx(w.value_sum).epsilon(1e-12));  // summed in another order
    }
    CHECK(got.size() == with_rows);
}

}  // namespace manikind::test
