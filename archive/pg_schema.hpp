#pragma once
// The archive's PostgreSQL schema (docs/archive.md): the tables many daemons' SQLite files are
// pushed into, keyed so that a row sent twice changes nothing. Migrated like the recorder's
// SQLite schema: an append-only list, each step in its own transaction, the version in
// schema_version.
#include <span>

#include "archive/pg.hpp"

namespace manikind::archive {

// Migration i (0-based) takes the archive from version i to i + 1. Never edit a released entry.
std::span<const char* const> pg_migrations();
int pg_latest_schema_version();

// Brings the archive to the latest version and returns it. Pushers may migrate at the same
// time: an advisory lock makes them take turns. UserError (status 4) if the archive's schema is
// newer than this program.
int migrate_archive(PgConnection& pg);

}  // namespace manikind::archive
