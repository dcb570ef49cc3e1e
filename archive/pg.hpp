#pragma once
// A thin owner of one libpq connection for the archive (docs/archive.md): commands that throw
// manikind::UserError with the server's message, so `manikin archive push` reports what failed
// under the CLI's exit statuses (docs/cli.md): 3 when the server cannot be reached or the
// connection is lost, 4 when the server refuses a statement, 2 for a malformed conninfo.
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <libpq-fe.h>

namespace manikind::archive {

// libpq, loaded by the first archive command rather than at every program's start
// (base/lazy_library.hpp); each member is the PQ function of the same name without "PQ".
struct Libpq {
    decltype(&::PQclear) clear = nullptr;
    decltype(&::PQcmdTuples) cmdTuples = nullptr;
    decltype(&::PQconnectdbParams) connectdbParams = nullptr;
    decltype(&::PQconninfoFree) conninfoFree = nullptr;
    decltype(&::PQconninfoParse) conninfoParse = nullptr;
    decltype(&::PQdb) db = nullptr;
    decltype(&::PQerrorMessage) errorMessage = nullptr;
    decltype(&::PQescapeLiteral) escapeLiteral = nullptr;
    decltype(&::PQexec) exec = nullptr;
    decltype(&::PQexecParams) execParams = nullptr;
    decltype(&::PQfinish) finish = nullptr;
    decltype(&::PQfreemem) freemem = nullptr;
    decltype(&::PQgetCopyData) getCopyData = nullptr;
    decltype(&::PQgetResult) getResult = nullptr;
    decltype(&::PQgetisnull) getisnull = nullptr;
    decltype(&::PQgetvalue) getvalue = nullptr;
    decltype(&::PQhost) host = nullptr;
    decltype(&::PQntuples) ntuples = nullptr;
    decltype(&::PQport) port = nullptr;
    decltype(&::PQputCopyData) putCopyData = nullptr;
    decltype(&::PQputCopyEnd) putCopyEnd = nullptr;
    decltype(&::PQresultErrorMessage) resultErrorMessage = nullptr;
    decltype(&::PQresultStatus) resultStatus = nullptr;
    decltype(&::PQsetClientEncoding) setClientEncoding = nullptr;
    decltype(&::PQstatus) status = nullptr;
};
// UserError (code missing_library) when libpq cannot be loaded; tried again at the next call.
const Libpq& libpq();

// One statement's result; frees itself.
class PgResult {
public:
    explicit PgResult(PGresult* r) : r_(r) {}
    PgResult(PgResult&& other) noexcept : r_(other.r_) { other.r_ = nullptr; }
    PgResult& operator=(PgResult&&) = delete;
    PgResult(const PgResult&) = delete;
    PgResult& operator=(const PgResult&) = delete;
    ~PgResult() { if (r_) libpq().clear(r_); }

    int rows() const { return libpq().ntuples(r_); }
    bool is_null(int row, int column) const { return libpq().getisnull(r_, row, column) != 0; }
    std::string text(int row, int column) const { return libpq().getvalue(r_, row, column); }
    std::int64_t int64(int row, int column) const;
    std::int64_t affected() const;  // PQcmdTuples: rows an INSERT/UPDATE touched

private:
    PGresult* r_;
};

class PgConnection {
public:
    // Connects; UserError (status 3, code archive_unreachable) naming the server when it fails,
    // status 2 when the conninfo itself does not parse.
    static PgConnection connect(const std::string& conninfo);
    // UserError (status 2) when `conninfo` does not parse as a libpq connection string or URI.
    static void check_conninfo(const std::string& conninfo);
    // The same parse without throwing on a bad conninfo: the parser's message (empty when it
    // parses) and whether it carries a password (the config check warns of one in a readable file).
    struct ConninfoParse {
        std::string error;
        bool has_password = false;
    };
    static ConninfoParse parse_conninfo(const std::string& conninfo);

    PgConnection(PgConnection&& other) noexcept : c_(other.c_) { other.c_ = nullptr; }
    PgConnection& operator=(PgConnection&&) = delete;
    PgConnection(const PgConnection&) = delete;
    PgConnection& operator=(const PgConnection&) = delete;
    ~PgConnection() { if (c_) libpq().finish(c_); }

    // One statement with text parameters ($1, $2 ...); exec_nullable for NULL parameters.
    PgResult exec(const std::string& sql, const std::vector<std::string>& params = {});
    // The same with a NULL wherever is_null[i].
    PgResult exec_nullable(const std::string& sql, const std::vector<std::string>& params,
                           const std::vector<bool>& is_null);
    // Several statements separated by ";" and no parameters (a migration).
    void exec_script(const std::string& sql);
    // Ends a failed transaction; never throws (the connection may already be gone).
    void rollback() noexcept { libpq().clear(libpq().exec(c_, "ROLLBACK")); }
    // COPY ... FROM STDIN with `data` as its whole input (text format, one row a line).
    void copy_in(const std::string& copy_sql, std::string_view data);

    std::string describe() const;  // "host:port/dbname" for messages
    PGconn* raw() { return c_; }

private:
    explicit PgConnection(PGconn* c) : c_(c) {}
    [[noreturn]] void fail(const std::string& what, const char* server_message) const;
    PGconn* c_;
};

// `s` as a field of COPY's text format: backslash, tab, newline and carriage return escaped.
void append_copy_text(std::string& out, std::string_view s);

}  // namespace manikind::archive
