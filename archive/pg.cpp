#include "archive/pg.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>

#include <fmt/core.h>

#include "base/lazy_library.hpp"
#include "base/user_error.hpp"

namespace manikind::archive {
namespace {

std::string trimmed(const char* message) {
    std::string s = message ? message : "";
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
    return s;
}

}  // namespace

const Libpq& libpq() {
    static LazyLibrary library("libmanikind-pq.so", "the PostgreSQL client library (libpq, for the archive)");
    return library.table<Libpq>([](LazyLibrary& l, Libpq& a) {
        MANIKIND_BIND(l, a, clear, PQclear);
        MANIKIND_BIND(l, a, cmdTuples, PQcmdTuples);
        MANIKIND_BIND(l, a, connectdbParams, PQconnectdbParams);
        MANIKIND_BIND(l, a, conninfoFree, PQconninfoFree);
        MANIKIND_BIND(l, a, conninfoParse, PQconninfoParse);
        MANIKIND_BIND(l, a, db, PQdb);
        MANIKIND_BIND(l, a, errorMessage, PQerrorMessage);
        MANIKIND_BIND(l, a, escapeLiteral, PQescapeLiteral);
        MANIKIND_BIND(l, a, exec, PQexec);
        MANIKIND_BIND(l, a, execParams, PQexecParams);
        MANIKIND_BIND(l, a, finish, PQfinish);
        MANIKIND_BIND(l, a, freemem, PQfreemem);
        MANIKIND_BIND(l, a, getCopyData, PQgetCopyData);
        MANIKIND_BIND(l, a, getResult, PQgetResult);
        MANIKIND_BIND(l, a, getisnull, PQgetisnull);
        MANIKIND_BIND(l, a, getvalue, PQgetvalue);
        MANIKIND_BIND(l, a, host, PQhost);
        MANIKIND_BIND(l, a, ntuples, PQntuples);
        MANIKIND_BIND(l, a, port, PQport);
        MANIKIND_BIND(l, a, putCopyData, PQputCopyData);
        MANIKIND_BIND(l, a, putCopyEnd, PQputCopyEnd);
        MANIKIND_BIND(l, a, resultErrorMessage, PQresultErrorMessage);
        MANIKIND_BIND(l, a, resultStatus, PQresultStatus);
        MANIKIND_BIND(l, a, setClientEncoding, PQsetClientEncoding);
        MANIKIND_BIND(l, a, status, PQstatus);
    });
}

std::int64_t PgResult::int64(int row, int column) const {
    return std::strtoll(libpq().getvalue(r_, row, column), nullptr, 10);
}

std::int64_t PgResult::affected() const {
    const char* n = libpq().cmdTuples(r_);
    return n && *n ? std::strtoll(n, nullptr, 10) : 0;
}

PgConnection::ConninfoParse PgConnection::parse_conninfo(const std::string& conninfo) {
    ConninfoParse out;
    char* parse_error = nullptr;
    PQconninfoOption* options = libpq().conninfoParse(conninfo.c_str(), &parse_error);
    if (!options) {
        out.error = parse_error ? trimmed(parse_error) : "out of memory";
        if (out.error.empty()) out.error = "does not parse";
        libpq().freemem(parse_error);
        return out;
    }
    for (const PQconninfoOption* o = options; o->keyword; ++o)
        if (std::string(o->keyword) == "password" && o->val && *o->val) out.has_password = true;
    libpq().conninfoFree(options);
    return out;
}

void PgConnection::check_conninfo(const std::string& conninfo) {
    const auto parsed = parse_conninfo(conninfo);
    if (!parsed.error.empty())
        throw UserError(fmt::format("archive conninfo '{}' does not parse: {}", conninfo, parsed.error), "bad_input");
}

PgConnection PgConnection::connect(const std::string& conninfo) {
    // Parsed first, so a typo in the conninfo is bad input (2), not an unreachable server (3).
    check_conninfo(conninfo);
    // A server that does not answer is given up after 10 s, and (over TCP) a connection whose
    // peer vanished after 60 s, unless the conninfo says otherwise: the daemon's forwarder retries
    // rather than hang. Entries after the expanded dbname override the ones before it.
    const char* const keywords[] = {"connect_timeout", "tcp_user_timeout", "dbname", nullptr};
    const char* const values[] = {"10", "60000", conninfo.c_str(), nullptr};
    PgConnection c(libpq().connectdbParams(keywords, values, 1));
    if (!c.c_) throw UserError::unreachable("libpq could not allocate a connection", "archive_unreachable");
    if (libpq().status(c.c_) != CONNECTION_OK)
        throw UserError::unreachable(
            fmt::format("cannot reach the archive server ({}): {}", conninfo, trimmed(libpq().errorMessage(c.c_))),
            "archive_unreachable");
    libpq().setClientEncoding(c.c_, "UTF8");
    // The migrations' "already exists, skipping" notices are not news to the person pushing.
    c.exec("SET client_min_messages = warning");
    return c;
}

std::string PgConnection::describe() const {
    const char* host = libpq().host(c_);
    const char* port = libpq().port(c_);
    const char* db = libpq().db(c_);
    return fmt::format("{}:{}/{}", host ? host : "?", port ? port : "?", db ? db : "?");
}

void PgConnection::fail(const std::string& what, const char* server_message) const {
    const std::string message = fmt::format("archive {}: {}: {}", describe(), what, trimmed(server_message));
    // A lost connection (server stopped, network gone) is "unreachable": the push can be run
    // again once the server is back, and resumes (docs/archive.md).
    if (libpq().status(c_) == CONNECTION_BAD) throw UserError::unreachable(message, "archive_unreachable");
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
    PGresult* r = libpq().execParams(c_, sql.c_str(), static_cast<int>(params.size()), nullptr, values.data(), nullptr,
                               nullptr, 0);
    const auto status = libpq().resultStatus(r);
    if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK) {
        const std::string server = r ? trimmed(libpq().resultErrorMessage(r)) : trimmed(libpq().errorMessage(c_));
        libpq().clear(r);
        // The statement's first line names it without pasting a whole migration into the message.
        fail(sql.substr(0, sql.find('\n', 1)), server.c_str());
    }
    return PgResult(r);
}

void PgConnection::exec_script(const std::string& sql) {
    PGresult* r = libpq().exec(c_, sql.c_str());
    const bool ok = libpq().resultStatus(r) == PGRES_COMMAND_OK || libpq().resultStatus(r) == PGRES_TUPLES_OK;
    const std::string server = r ? trimmed(libpq().resultErrorMessage(r)) : trimmed(libpq().errorMessage(c_));
    libpq().clear(r);
    if (!ok) fail("schema migration", server.c_str());
}

void PgConnection::copy_in(const std::string& copy_sql, std::string_view data) {
    PGresult* start = libpq().exec(c_, copy_sql.c_str());
    const bool ready = libpq().resultStatus(start) == PGRES_COPY_IN;
    const std::string start_error = start ? trimmed(libpq().resultErrorMessage(start)) : trimmed(libpq().errorMessage(c_));
    libpq().clear(start);
    if (!ready) fail(copy_sql, start_error.c_str());
    // Blocking connection: libpq().putCopyData sends or buffers everything; 1 MB pieces keep each
    // call's length within int.
    constexpr std::size_t piece_bytes = 1 << 20;
    for (std::size_t at = 0; at < data.size(); at += piece_bytes) {
        const auto n = std::min(piece_bytes, data.size() - at);
        if (libpq().putCopyData(c_, data.data() + at, static_cast<int>(n)) != 1) {
            libpq().putCopyEnd(c_, "send failed");
            fail(copy_sql, libpq().errorMessage(c_));
        }
    }
    if (libpq().putCopyEnd(c_, nullptr) != 1) fail(copy_sql, libpq().errorMessage(c_));
    std::string error;
    bool failed = false;
    while (PGresult* r = libpq().getResult(c_)) {  // the COPY's own result, then nullptr
        if (libpq().resultStatus(r) != PGRES_COMMAND_OK) {
            failed = true;
            error = trimmed(libpq().resultErrorMessage(r));
        }
        libpq().clear(r);
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
