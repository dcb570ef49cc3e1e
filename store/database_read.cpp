// The recording database's readers (store/database.hpp): campaigns, cases, trials, channels,
// samples (a trial's, the idle log's), events, notes, results, twin versions and set-ups, and
// the marks the daemon counts stored rows by.
#include "store/database_impl.hpp"

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <fmt/core.h>

namespace manikind::recorder {

std::optional<std::int64_t> Database::find_campaign(const std::string& name) {
    Query q(*impl_, "SELECT id FROM campaigns WHERE name = ?");
    q.bind(name);
    if (!q.step()) return std::nullopt;
    return q.integer(0);
}

std::vector<NoteRow> Database::notes(std::int64_t campaign_id) {
    Query q(*impl_, "SELECT id, campaign_id, trial_id, utc_ns, author, kind, text FROM notes WHERE campaign_id = ? ORDER BY utc_ns, id");
    q.bind(campaign_id);
    std::vector<NoteRow> out;
    while (q.step()) out.push_back({q.integer(0), q.integer(1), q.optional_integer(2), q.integer(3), q.text(4), q.text(5), q.text(6)});
    return out;
}

std::optional<SetupRow> Database::setup(std::int64_t setup_id) {
    Query q(*impl_,
            "SELECT id, sha256, first_used_utc_ns, lab_name, chamber, manikin, calibration_json, config_toml"
            " FROM setups WHERE id = ?");
    q.bind(setup_id);
    if (!q.step()) return std::nullopt;
    SetupRow row;
    row.id = q.integer(0);
    row.sha256 = q.text(1);
    row.first_used_utc_ns = q.integer(2);
    row.setup = {q.text(3), q.text(4), q.text(5), q.text(6), q.text(7)};
    return row;
}

std::optional<std::string> Database::twin_version_toml(const std::string& name, std::int64_t version) {
    Query q(*impl_, "SELECT toml FROM twin_versions WHERE name = ? AND version = ?");
    q.bind(name, version);
    if (!q.step()) return std::nullopt;
    return q.text(0);
}

std::optional<std::string> Database::latest_twin_version() {
    Query q(*impl_, "SELECT name, version FROM twin_versions ORDER BY created_utc_ns DESC, id DESC LIMIT 1");
    if (!q.step()) return std::nullopt;
    return q.text(0) + " v" + std::to_string(q.integer(1));
}

std::vector<CampaignRow> Database::campaigns() {
    Query q(*impl_, "SELECT id, name, definition_json, created_utc_ns, state FROM campaigns ORDER BY id");
    std::vector<CampaignRow> out;
    while (q.step()) out.push_back({q.integer(0), q.text(1), q.text(2), q.integer(3), q.text(4)});
    return out;
}

std::vector<CaseRow> Database::cases(std::int64_t campaign_id) {
    Query q(*impl_,
            "SELECT id, campaign_id, name, conditions_json, position FROM cases WHERE campaign_id = ?"
            " ORDER BY position, id");
    q.bind(campaign_id);
    std::vector<CaseRow> out;
    while (q.step()) out.push_back({q.integer(0), q.integer(1), q.text(2), q.text(3), q.integer(4)});
    return out;
}

namespace {
constexpr const char* trial_columns =
    "SELECT id, campaign_id, case_id, replicate, state, reason, started_utc_ns, ended_utc_ns, steady_from_mono_ns,"
    " quality_flags, uuid, setup_id FROM trials ";

TrialRow read_trial(const Query& q) {
    return {q.integer(0),          q.integer(1),          q.integer(2),          q.integer(3), q.text(4), q.text(5),
            q.optional_integer(6), q.optional_integer(7), q.optional_integer(8), q.integer(9), q.text(10),
            q.optional_integer(11)};
}
}  // namespace

std::vector<TrialRow> Database::trials(std::int64_t campaign_id) {
    static const std::string sql = std::string(trial_columns) + "WHERE campaign_id = ? ORDER BY id";
    Query q(*impl_, sql);
    q.bind(campaign_id);
    std::vector<TrialRow> out;
    while (q.step()) out.push_back(read_trial(q));
    return out;
}

std::optional<TrialRow> Database::trial(std::int64_t trial_id) {
    static const std::string sql = std::string(trial_columns) + "WHERE id = ?";
    Query q(*impl_, sql);
    q.bind(trial_id);
    if (!q.step()) return std::nullopt;
    return read_trial(q);
}

std::vector<ChannelRow> Database::channels() {
    Query q(*impl_,
            "SELECT c.id, c.device_id, d.name, c.name, c.unit FROM channels c JOIN devices d ON d.id = c.device_id"
            " ORDER BY d.name, c.name");
    std::vector<ChannelRow> out;
    while (q.step()) out.push_back({q.integer(0), q.integer(1), q.text(2), q.text(3), q.text(4)});
    return out;
}

std::vector<SampleRow> Database::samples(std::int64_t trial_id, std::int64_t channel_id) {
    Query q(*impl_,
            "SELECT mono_ns, utc_ns, value, quality FROM samples WHERE id >= ?1 AND id < ?2 AND channel_id = ?3"
            " ORDER BY mono_ns");
    q.bind(trial_id_begin(trial_id), trial_id_end(trial_id), channel_id);
    std::vector<SampleRow> out;
    while (q.step())
        out.push_back({trial_id, channel_id, q.integer(0), q.integer(1), q.real(2), static_cast<std::uint8_t>(q.integer(3))});
    return out;
}

void Database::for_each_trial_sample(std::int64_t trial_id, const std::function<void(const SampleRow&)>& visit) {
    // Read in stored order and sorted here, not by ORDER BY: SQLite's sorter spills a trial
    // (180 000 rows) to temporary files beyond its 2 MB cache, which made the demo 20 % slower.
    // Stored order is already time order per device, so the sort mostly orders channels
    // within an instant. Memory: one trial.
    std::vector<SampleRow> rows;
    {
        // Sized once: a trial's ids run from its range's start without gaps but for rows a
        // failed write left out, so the last id bounds the count, found by two key lookups.
        // Growing by doubling instead held the old and the new buffer at once (26 MB for a
        // trial of 182 000 rows), the peak of an export.
        Query last(*impl_, "SELECT max(id) FROM samples WHERE id >= ?1 AND id < ?2");
        last.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
        if (last.step() && last.optional_integer(0)) {
            const auto span = *last.optional_integer(0) - trial_id_begin(trial_id) + 1;
            if (span > 0 && span < (std::int64_t{1} << 28)) rows.reserve(static_cast<std::size_t>(span));
        }
    }
    {
        Query q(*impl_, "SELECT mono_ns, channel_id, utc_ns, value, quality FROM samples WHERE id >= ?1 AND id < ?2");
        q.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
        while (q.step())
            rows.push_back({trial_id, q.integer(1), q.integer(0), q.integer(2), q.real(3), static_cast<std::uint8_t>(q.integer(4))});
    }
    const auto by_time = [](const SampleRow& a, const SampleRow& b) {
        return a.mono_ns != b.mono_ns ? a.mono_ns < b.mono_ns : a.channel_id < b.channel_id;
    };
    if (!std::is_sorted(rows.begin(), rows.end(), by_time)) std::sort(rows.begin(), rows.end(), by_time);
    for (const auto& row : rows) visit(row);
}

std::vector<SampleRow> Database::idle_samples(std::int64_t channel_id, std::int64_t since_utc_ns) {
    // Keyed (utc_ns, channel_id): the time bound is the key range, the channel a filter.
    Query q(*impl_, "SELECT mono_ns, utc_ns, value, quality FROM idle_samples WHERE utc_ns >= ? AND channel_id = ? ORDER BY utc_ns");
    q.bind(since_utc_ns, channel_id);
    std::vector<SampleRow> out;
    while (q.step())
        out.push_back({0, channel_id, q.integer(0), q.integer(1), q.real(2), static_cast<std::uint8_t>(q.integer(3))});
    return out;
}

std::optional<std::int64_t> Database::newest_idle_utc_ns() {
    Query q(*impl_, "SELECT max(utc_ns) FROM idle_samples");
    q.step();
    return q.optional_integer(0);
}

std::optional<std::int64_t> Database::newest_utc_ns() {
    // Three key lookups and a scan of the (small) events table: samples are a rowid range per
    // trial in trial order, the idle log is keyed by utc_ns first.
    std::optional<std::int64_t> newest = newest_idle_utc_ns();
    for (const char* sql : {"SELECT utc_ns FROM samples ORDER BY id DESC LIMIT 1", "SELECT max(utc_ns) FROM events"}) {
        Query q(*impl_, sql);
        if (!q.step()) continue;
        if (const auto v = q.optional_integer(0); v && (!newest || *v > *newest)) newest = v;
    }
    return newest;
}

std::int64_t Database::idle_sample_count() {
    Query q(*impl_, "SELECT count(*) FROM idle_samples");
    q.step();
    return q.integer(0);
}

Database::RowMark Database::row_mark() {
    RowMark mark;
    {
        Query q(*impl_, "SELECT max(id) FROM samples");
        q.step();
        mark.sample_id = q.optional_integer(0).value_or(-1);
    }
    mark.idle_rows = idle_sample_count();
    return mark;
}

std::int64_t Database::rows_since(const RowMark& mark) {
    std::int64_t n = 0;
    {
        Query q(*impl_, "SELECT count(*) FROM samples WHERE id > ?1");
        q.bind(mark.sample_id);
        q.step();
        n += q.integer(0);
    }
    return n + idle_sample_count() - mark.idle_rows;
}

std::int64_t Database::sample_count(std::int64_t trial_id) {
    Query q(*impl_, "SELECT count(*) FROM samples WHERE id >= ?1 AND id < ?2");
    q.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
    q.step();
    return q.integer(0);
}

std::optional<std::int64_t> Database::last_sample_mono_ns(std::int64_t trial_id) {
    Query q(*impl_, "SELECT max(mono_ns) FROM samples WHERE id >= ?1 AND id < ?2");
    q.bind(trial_id_begin(trial_id), trial_id_end(trial_id));
    if (!q.step()) return std::nullopt;
    return q.optional_integer(0);
}

std::vector<EventRow> Database::events(std::optional<std::int64_t> trial_id) {
    // Two statements rather than "?1 IS NULL OR trial_id = ?1", which the planner cannot
    // answer from events_by_trial_time.
    Query q = trial_id ? Query(*impl_, "SELECT id, trial_id, mono_ns, utc_ns, severity, kind, message FROM events"
                                       " WHERE trial_id = ? ORDER BY mono_ns, id")
                       : Query(*impl_, "SELECT id, trial_id, mono_ns, utc_ns, severity, kind, message FROM events"
                                       " ORDER BY mono_ns, id");
    if (trial_id) q.bind(*trial_id);
    std::vector<EventRow> out;
    while (q.step())
        out.push_back({q.integer(0), q.optional_integer(1), q.integer(2), q.integer(3), q.text(4), q.text(5), q.text(6)});
    return out;
}

std::optional<ResultRow> Database::latest_result(std::int64_t campaign_id) {
    Query q(*impl_,
            "SELECT id, campaign_id, computed_utc_ns, json FROM results WHERE campaign_id = ?"
            " ORDER BY computed_utc_ns DESC, id DESC LIMIT 1");
    q.bind(campaign_id);
    if (!q.step()) return std::nullopt;
    return ResultRow{q.integer(0), q.integer(1), q.integer(2), q.text(3)};
}

}  // namespace manikind::recorder
