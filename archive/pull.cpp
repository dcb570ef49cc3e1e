#include "archive/pull.hpp"

#include <sqlite3.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

#include <fmt/core.h>

#include "archive/pg.hpp"
#include "base/user_error.hpp"

namespace manikind::archive {
namespace {

// Rows handed to insert_samples at once: one SQLite transaction each, bounded memory.
constexpr std::size_t sample_batch_rows = 100'000;

std::optional<std::int64_t> opt_int64(const PgResult& r, int row, int column) {
    if (r.is_null(row, column)) return std::nullopt;
    return r.int64(row, column);
}

// One field of COPY's text format back to its text (the inverse of append_copy_text, plus the
// escapes the server may write: \b \f \v, octal and \x).
std::string decode_copy_text(std::string_view s) {
    std::string out;
    out.reserve(s.size());
    for (std::size_t i = 0; i < s.size(); ++i) {
        if (s[i] != '\\' || i + 1 == s.size()) {
            out += s[i];
            continue;
        }
        const char c = s[++i];
        switch (c) {
            case 'b': out += '\b'; break;
            case 'f': out += '\f'; break;
            case 'n': out += '\n'; break;
            case 'r': out += '\r'; break;
            case 't': out += '\t'; break;
            case 'v': out += '\v'; break;
            case 'x': {
                int v = 0, digits = 0;
                while (digits < 2 && i + 1 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1]))) {
                    const char h = s[++i];
                    v = v * 16 + (h <= '9' ? h - '0' : (h | 0x20) - 'a' + 10);
                    ++digits;
                }
                out += digits ? static_cast<char>(v) : 'x';
                break;
            }
            default:
                if (c >= '0' && c <= '7') {
                    int v = c - '0';
                    for (int digits = 1; digits < 3 && i + 1 < s.size() && s[i + 1] >= '0' && s[i + 1] <= '7'; ++digits)
                        v = v * 8 + (s[++i] - '0');
                    out += static_cast<char>(v);
                } else {
                    out += c;  // \\ and any other character stand for themselves
                }
        }
    }
    return out;
}

// The fields of one COPY text row (its trailing newline dropped), still escaped.
std::vector<std::string_view> split_copy_row(std::string_view line) {
    if (!line.empty() && line.back() == '\n') line.remove_suffix(1);
    std::vector<std::string_view> fields;
    std::size_t start = 0;
    for (std::size_t tab; (tab = line.find('\t', start)) != std::string_view::npos; start = tab + 1)
        fields.push_back(line.substr(start, tab - start));
    fields.push_back(line.substr(start));
    return fields;
}

// `what` names the row in the message when the server sent something this program cannot read.
std::int64_t parse_int64(std::string_view s, const char* what) {
    std::int64_t v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size())
        throw UserError(fmt::format("archive: {} '{}' is not an integer", what, s), "archive_refused",
                        ExitStatus::refused);
    return v;
}

// double precision as COPY writes it; NULL is the recorder's NaN (the push stored NaN as NULL).
double parse_value(std::string_view s) {
    if (s == "\\N" || s == "NaN") return std::numeric_limits<double>::quiet_NaN();
    if (s == "Infinity") return std::numeric_limits<double>::infinity();
    if (s == "-Infinity") return -std::numeric_limits<double>::infinity();
    double v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size())
        throw UserError(fmt::format("archive: sample value '{}' is not a number", s), "archive_refused",
                        ExitStatus::refused);
    return v;
}

// COPY (...) TO STDOUT, one text row at a time to `row` (blocking: libpq().getCopyData waits for each).
template <typename RowFn>
void copy_out(PgConnection& pg, const std::string& copy_sql, RowFn&& row) {
    PGconn* c = pg.raw();
    const auto failure = [&](const std::string& server) {
        const std::string message = fmt::format("archive {}: {}: {}", pg.describe(), copy_sql.substr(0, 60), server);
        if (libpq().status(c) == CONNECTION_BAD) return UserError::unreachable(message, "archive_unreachable");
        return UserError(message, "archive_refused", ExitStatus::refused);
    };
    PGresult* start = libpq().exec(c, copy_sql.c_str());
    const bool ready = libpq().resultStatus(start) == PGRES_COPY_OUT;
    const std::string start_error = start ? libpq().resultErrorMessage(start) : libpq().errorMessage(c);
    libpq().clear(start);
    if (!ready) throw failure(start_error);
    for (;;) {
        char* buffer = nullptr;
        const int n = libpq().getCopyData(c, &buffer, 0);
        if (n == -1) break;  // the end of the data; the COPY's own result follows
        if (n < 0) throw failure(libpq().errorMessage(c));
        std::unique_ptr<char, decltype(libpq().freemem)> owned(buffer, libpq().freemem);
        row(std::string_view(buffer, static_cast<std::size_t>(n)));
    }
    std::string error;
    while (PGresult* r = libpq().getResult(c)) {
        if (libpq().resultStatus(r) != PGRES_COMMAND_OK) error = libpq().resultErrorMessage(r);
        libpq().clear(r);
    }
    if (!error.empty()) throw failure(error);
}

// A quoted SQL literal for COPY, which takes no parameters.
std::string literal(PgConnection& pg, const std::string& s) {
    char* quoted = libpq().escapeLiteral(pg.raw(), s.c_str(), s.size());
    if (!quoted) throw UserError(fmt::format("archive {}: cannot quote '{}'", pg.describe(), s), "archive_refused",
                                 ExitStatus::refused);
    std::string out(quoted);
    libpq().freemem(quoted);
    return out;
}

// What the Database API cannot set on a row it creates (a trial's UUID and exact times, a
// campaign's creation time), written through a second connection to the same file.
class SqliteFixups {
public:
    explicit SqliteFixups(const std::filesystem::path& path) : path_(path) {
        sqlite3* db = nullptr;
        const int rc = sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr);
        db_.reset(db);
        if (rc != SQLITE_OK) fail();
        sqlite3_busy_timeout(db, 5000);
    }

    void run(const char* sql, const std::vector<std::optional<std::int64_t>>& ints, const std::string& text = {}) {
        sqlite3_stmt* raw = nullptr;
        if (sqlite3_prepare_v2(db_.get(), sql, -1, &raw, nullptr) != SQLITE_OK) fail();
        std::unique_ptr<sqlite3_stmt, decltype(&sqlite3_finalize)> s(raw, &sqlite3_finalize);
        int i = 1;
        for (const auto& v : ints) {
            if (v) sqlite3_bind_int64(raw, i++, *v);
            else sqlite3_bind_null(raw, i++);
        }
        if (!text.empty()) sqlite3_bind_text(raw, i, text.c_str(), -1, SQLITE_TRANSIENT);
        if (sqlite3_step(raw) != SQLITE_DONE) fail();
    }

private:
    [[noreturn]] void fail() const {
        throw UserError(fmt::format("{}: {}", path_.string(), db_ ? sqlite3_errmsg(db_.get()) : "out of memory"));
    }
    struct Close {
        void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
    };
    std::filesystem::path path_;
    std::unique_ptr<sqlite3, Close> db_;
};

struct ArchivedTrial {
    std::string uuid, case_name, state, reason, conditions_json;
    std::int64_t replicate = 0;
    std::optional<std::int64_t> started_utc_ns, ended_utc_ns;
    std::int64_t id = 0;  // in `into`
};

}  // namespace

PullResult pull_campaign(const std::string& conninfo, const std::string& lab_id, const std::string& campaign_name,
                         recorder::Database& into) {
    auto pg = PgConnection::connect(conninfo);
    PullResult result;
    result.archive = pg.describe();
    if (pg.exec("SELECT to_regclass('trials') IS NOT NULL AND to_regclass('labs') IS NOT NULL").text(0, 0) != "t")
        throw UserError(
            fmt::format("archive {} holds no manikind archive yet (nothing was pushed there)", result.archive));
    // One snapshot for the whole pull: a push running meanwhile adds nothing half-way.
    pg.exec("BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY");
    // Shortest exact text for every double (PostgreSQL 12+; 17 digits before): values bit for bit.
    pg.exec("SET LOCAL extra_float_digits = 3");

    if (pg.exec("SELECT 1 FROM labs WHERE lab_id = $1", {lab_id}).rows() == 0) {
        auto labs = pg.exec("SELECT lab_id FROM labs ORDER BY lab_id");
        std::string known;
        for (int i = 0; i < labs.rows(); ++i) known += (i ? ", " : "") + labs.text(i, 0);
        throw UserError(fmt::format("archive {}: no lab '{}' (labs there: {})", result.archive, lab_id,
                                    known.empty() ? "none" : known),
                        "unknown_lab");
    }
    auto campaign = pg.exec("SELECT definition_json, created_utc_ns, state FROM campaigns"
                            " WHERE lab_id = $1 AND campaign_name = $2",
                            {lab_id, campaign_name});
    if (campaign.rows() == 0) {
        auto names = pg.exec("SELECT campaign_name FROM campaigns WHERE lab_id = $1"
                             " ORDER BY created_utc_ns, campaign_name",
                             {lab_id});
        std::string known;
        for (int i = 0; i < names.rows(); ++i) known += (i ? ", " : "") + names.text(i, 0);
        throw UserError(fmt::format("archive {}: lab '{}' has no campaign '{}' (its campaigns: {})", result.archive,
                                    lab_id, campaign_name, known.empty() ? "none" : known),
                        "unknown_campaign");
    }
    if (into.find_campaign(campaign_name))
        throw UserError(fmt::format("{}: already holds a campaign '{}'", into.path().string(), campaign_name));

    // Trials in the order they ran (the recorder's ids follow it, and campaign_from_database
    // lists trials by id); one that never started goes last.
    auto rows = pg.exec("SELECT trial_uuid, case_name, replicate, state, reason, started_utc_ns, ended_utc_ns,"
                        " conditions_json FROM trials WHERE lab_id = $1 AND campaign_name = $2"
                        " ORDER BY started_utc_ns NULLS LAST, ended_utc_ns NULLS LAST, replicate, trial_uuid",
                        {lab_id, campaign_name});
    std::vector<ArchivedTrial> trials;
    for (int i = 0; i < rows.rows(); ++i)
        trials.push_back({rows.text(i, 0), rows.text(i, 1), rows.text(i, 3), rows.text(i, 4), rows.text(i, 7),
                          rows.int64(i, 2), opt_int64(rows, i, 5), opt_int64(rows, i, 6)});

    // Cases: the archive keeps each trial's case name and conditions, not the case list. Their
    // order is the one the first replicate ran them in (the daemon runs replicate 1 in the plan's
    // order); the conditions keep the case's "id", which is what the analysis numbers cases by.
    std::vector<const ArchivedTrial*> by_replicate;
    for (const auto& t : trials) by_replicate.push_back(&t);
    std::stable_sort(by_replicate.begin(), by_replicate.end(),
                     [](const ArchivedTrial* a, const ArchivedTrial* b) { return a->replicate < b->replicate; });

    SqliteFixups fix(into.path());
    const auto campaign_id = into.create_campaign(campaign_name, campaign.text(0, 0));
    into.set_campaign_state(campaign_id, campaign.text(0, 2));
    fix.run("UPDATE campaigns SET created_utc_ns = ?1 WHERE id = ?2", {campaign.int64(0, 1), campaign_id});

    std::map<std::string, std::int64_t> case_ids;  // case name -> id in `into`
    for (const auto* t : by_replicate)
        if (!case_ids.count(t->case_name)) {
            case_ids[t->case_name] = into.add_case(campaign_id, t->case_name, t->conditions_json, result.cases);
            ++result.cases;
        }

    // Trials: the API's row, then the archive's UUID and exact times (set_trial_state would take
    // the first state change as the start).
    std::map<std::string, std::int64_t> trial_ids;  // UUID -> id in `into`
    for (auto& t : trials) {
        t.id = into.create_trial(campaign_id, case_ids.at(t.case_name), t.replicate);
        if (t.state != "pending")
            into.set_trial_state(t.id, t.state, t.reason, t.ended_utc_ns.value_or(t.started_utc_ns.value_or(0)));
        fix.run("UPDATE trials SET started_utc_ns = ?1, ended_utc_ns = ?2, uuid = ?4 WHERE id = ?3",
                {t.started_utc_ns, t.ended_utc_ns, t.id}, t.uuid);
        trial_ids[t.uuid] = t.id;
        ++result.trials;
    }

    // Every channel of the lab, named as pushed: campaign_from_database gives columns only to the
    // ones with samples. The archive has no device kind or address.
    std::map<std::pair<std::string, std::string>, std::int64_t> channel_ids;
    std::map<std::string, std::int64_t> device_ids;
    const auto channel_id = [&](const std::string& device, const std::string& channel, const std::string& unit) {
        const auto key = std::make_pair(device, channel);
        if (const auto it = channel_ids.find(key); it != channel_ids.end()) return it->second;
        if (!device_ids.count(device)) device_ids[device] = into.device_id(device, "archive", "");
        return channel_ids[key] = into.channel_id(device_ids[device], channel, unit);
    };
    auto channels = pg.exec("SELECT device, channel, unit FROM channels WHERE lab_id = $1 ORDER BY device, channel",
                            {lab_id});
    for (int i = 0; i < channels.rows(); ++i) channel_id(channels.text(i, 0), channels.text(i, 1), channels.text(i, 2));

    // Events: the campaign's trials' (their "stage" events bound each trial's time base) and the
    // lab's "config" events (the configuration's hash in the provenance).
    auto events = pg.exec("SELECT e.trial_uuid, e.mono_ns, e.utc_ns, e.severity, e.kind, e.message FROM events e"
                          " LEFT JOIN trials t ON t.trial_uuid = e.trial_uuid WHERE e.lab_id = $1"
                          " AND ((t.lab_id = $1 AND t.campaign_name = $2)"
                          " OR (e.trial_uuid IS NULL AND e.kind = 'config'))"
                          " ORDER BY e.mono_ns, e.utc_ns",
                          {lab_id, campaign_name});
    for (int i = 0; i < events.rows(); ++i) {
        std::optional<std::int64_t> trial;
        if (!events.is_null(i, 0)) trial = trial_ids.at(events.text(i, 0));
        into.add_event(trial, events.int64(i, 1), events.int64(i, 2), events.text(i, 3), events.text(i, 4),
                       events.text(i, 5));
        ++result.events;
    }

    // The lab notebook (an archive from before it, schema < 4, has none).
    if (pg.exec("SELECT to_regclass('notes') IS NOT NULL").text(0, 0) == "t") {
        auto notes = pg.exec("SELECT trial_uuid, utc_ns, author, kind, text FROM notes WHERE lab_id = $1 AND campaign_name = $2"
                             " ORDER BY utc_ns",
                             {lab_id, campaign_name});
        for (int i = 0; i < notes.rows(); ++i) {
            recorder::NoteRow n;
            n.campaign_id = campaign_id;
            if (!notes.is_null(i, 0)) {
                const auto it = trial_ids.find(notes.text(i, 0));
                if (it != trial_ids.end()) n.trial_id = it->second;
            }
            n.utc_ns = notes.int64(i, 1);
            n.author = notes.text(i, 2);
            n.kind = notes.text(i, 3);
            n.text = notes.text(i, 4);
            into.add_note(n);
            ++result.notes;
        }
    }

    // Samples: one COPY per trial, in batches into SQLite.
    std::vector<recorder::SampleRow> batch;
    batch.reserve(sample_batch_rows);
    const auto flush = [&] {
        into.insert_samples(batch);
        batch.clear();
    };
    for (const auto& t : trials) {
        const std::string sql = "COPY (SELECT device, channel, mono_ns, utc_ns, value, quality FROM samples"
                                " WHERE trial_uuid = " + literal(pg, t.uuid) + " ORDER BY mono_ns) TO STDOUT";
        copy_out(pg, sql, [&](std::string_view line) {
            const auto f = split_copy_row(line);
            if (f.size() != 6)
                throw UserError(fmt::format("archive {}: a sample row has {} fields, not 6", result.archive, f.size()),
                                "archive_refused", ExitStatus::refused);
            recorder::SampleRow row;
            row.trial_id = t.id;
            row.channel_id = channel_id(decode_copy_text(f[0]), decode_copy_text(f[1]), "");
            row.mono_ns = parse_int64(f[2], "sample mono_ns");
            row.utc_ns = parse_int64(f[3], "sample utc_ns");
            row.value = parse_value(f[4]);
            row.quality = static_cast<std::uint8_t>(parse_int64(f[5], "sample quality"));
            batch.push_back(row);
            ++result.samples;
            if (batch.size() >= sample_batch_rows) flush();
        });
    }
    if (!batch.empty()) flush();
    pg.exec("COMMIT");
    into.refresh_trial_table();
    return result;
}

}  // namespace manikind::archive
