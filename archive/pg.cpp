#include "archive/pg.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>

#include <fmt/core.h>

#include "base/user_error.hpp"

namespace manikind::archive {
namespace {

std::string trimmed(const char* message) {
    std::string s = message ? message : "";
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
    return s;
}

}  // namespace

std::int64_t PgResult::int64(int row, int column) const {
    return std::strtoll(PQgetvalue(r_, row, column), nullptr, 10);
}

std::int64_t PgResult::affected() const {
    const char* n = PQcmdTuples(r_);
    return n && *n ? std::strtoll(n, nullptr, 10) : 0;
}

void PgConnection::check_conninfo(const std::string& conninfo) {
    char* parse_error = nullptr;
    PQconninfoOption* options = PQconninfoParse(conninfo.c_str(), &parse_error);
    if (!options) {
        const std::string why = trimmed(parse_error);
        PQfreemem(parse_error);
        throw UserError(fmt::format("archive conninfo '{}' does not parse: {}", conninfo, why), "bad_input");
    }
    PQconninfoFree(options);
}

PgConnection PgConnection::connect(const std::string& conninfo) {
    // Parsed first, so a typo in the conninfo is bad input (2), not an unreachable server (3).
    check_conninfo(conninfo);
    // A server that does not answer is given up after 10 s, and (over TCP) a connection whose
    // peer vanished after 60 s, unless the conninfo says otherwise: the daemon's forwarder retries
    // rather than hang. Entries after the expanded dbname override the ones before it.
    const char* const keywords[] = {"connect_timeout", "tcp_user_timeout", "dbname", nullptr};
    const char* const values[] = {"10", "60000", conninfo.c_str(), nullptr};
    PgConnection c(PQconnectdbParams(keywords, values, 1));
    if (!c.c_) throw UserError::unreachable("libpq could not allocate a connection", "archive_unreachable");
    if (PQstatus(c.c_) != CONNECTION_OK)
        throw UserError::unreachable(
            fmt::format("cannot reach the archive server ({}): {}", conninfo, trimmed(PQerrorMessage(c.c_))),
            "archive_unreachable");
    PQsetClientEncoding(c.c_, "UTF8");
    // The migrations' "already exists, skipping" notices are not news to the person pushing.
    c.exec("SET client_min_messages = warning");
    return c;
}

std::string PgConnection::describe() const {
    const char* host = PQhost(c_);
    const char* port = PQport(c_);
    const char* db = PQdb(c_);
    return fmt::format("{}:{}/{}", host ? host : "?", port ? port : "?", db ? db : "?");
}

void PgConnection::fail(const std::string& what, const char* server_message) const {
    const std::string message = fmt::format("archive {}: {}: {}", describe(), what, trimmed(server_message));
    // A lost connection (server stopped, network gone) is "unreachable": the push can be run
    // again once the server is back, and resumes (docs/archive.md).
    if (PQstatus(c_) == CONNECTION_BAD) throw UserError::unreachable(message, "archive_unreachable");
    throw UserError(message, "archive_refused", ExitStatus::refused);
}

PgResult PgConnection::exec(const std::string& sql, const std::vector<std::string>& params) {
    return exec_nullable(sql, params, std::vector<bool>(params.size(), false));
}

PgResult PgConnection::exec_nullable(const std::string& sql, const std::vector<std::string>& params,
                                     const std::vector<bool>& is_null) {
    std::vector<const char*> values;
    values.reserve(params.size());
    for (std::size_t i = 0; i < params.size(); ++i) values.push_back(is_null[i] ? nullptr : params[i].c_str());
    PGresult* r = PQexecParams(c_, sql.c_str(), static_cast<int>(params.size()), nullptr, values.data(), nullptr,
                               nullptr, 0);
    const auto status = PQresultStatus(r);
    if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK) {
        const std::string server = r ? trimmed(PQresultErrorMessage(r)) : trimmed(PQerrorMessage(c_));
        PQclear(r);
        // The statement's first line names it without pasting a whole migration into the message.
        fail(sql.substr(0, sql.find('\n', 1)), server.c_str());
    }
    return PgResult(r);
}

void PgConnection::exec_script(const std::string& sql) {
    PGresult* r = PQexec(c_, sql.c_str());
    const bool ok = PQresultStatus(r) == PGRES_COMMAND_OK || PQresultStatus(r) == PGRES_TUPLES_OK;
    const std::string server = r ? trimmed(PQresultErrorMessage(r)) : trimmed(PQerrorMessage(c_));
    PQclear(r);
    if (!ok) fail("schema migration", server.c_str());
}

void PgConnection::copy_in(const std::string& copy_sql, std::string_view data) {
    PGresult* start = PQexec(c_, copy_sql.c_str());
    const bool ready = PQresultStatus(start) == PGRES_COPY_IN;
    const std::string start_error = start ? trimmed(PQresultErrorMessage(start)) : trimmed(PQerrorMessage(c_));
    PQclear(start);
    if (!ready) fail(copy_sql, start_error.c_str());
    // Blocking connection: PQputCopyData sends or buffers everything; 1 MB pieces keep each
    // call's length within int.
    constexpr std::size_t piece_bytes = 1 << 20;
    for (std::size_t at = 0; at < data.size(); at += piece_bytes) {
        const auto n = std::min(piece_bytes, data.size() - at);
        if (PQputCopyData(c_, data.data() + at, static_cast<int>(n)) != 1) {
            PQputCopyEnd(c_, "send failed");
            fail(copy_sql, PQerrorMessage(c_));
        }
    }
    if (PQputCopyEnd(c_, nullptr) != 1) fail(copy_sql, PQerrorMessage(c_));
    std::string error;
    bool failed = false;
    while (PGresult* r = PQgetResult(c_)) {  // the COPY's own result, then nullptr
        if (PQresultStatus(r) != PGRES_COMMAND_OK) {
            failed = true;
            error = trimmed(PQresultErrorMessage(r));
        }
        PQclear(r);
    }
    if (failed) fail(copy_sql, error.c_str());
}

void append_copy_text(std::string& out, std::string_view s) {
    for (const char ch : s) {
        switch (ch) {
            case '\\': out += "\\\\"; break;
            case '\t': out += "\\t"; break;
            case '\n': out += "\\n"; break;
            case '\r': out += "\\r"; break;
            default: out += ch;
        }
    }
}

}  // namespace manikind::archive
