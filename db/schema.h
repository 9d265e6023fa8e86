// The store's schema and its migrations. The schema version lives in `PRAGMA user_version`; migration N takes a
// database from version N-1 to N. Open() applies the missing ones in one write transaction, so a database is
// always at a version this list names (docs/store.md).
//
// Internal to db/; the list and Migrate() are exposed so tests can exercise the machinery with extra steps.
#pragma once

#include <span>
#include <string>

#include "common/status.h"
#include "db/sqlite_conn.h"

namespace vb::db::schema {

struct Migration {
  int version;              // the user_version after this step: 1, 2, ... with no gaps
  const char* description;  // one line, for docs and errors
  const char* sql;          // one or more statements
};

// The migrations this build knows, in order; kMigrations.back().version is the current schema version.
std::span<const Migration> Migrations();
int CurrentVersion();

// The database's user_version (0 for a new, empty file). Reads only.
StatusOr<int> ReadVersion(sql::Connection* conn);

// FailedPrecondition when `version` is newer than the newest of `migrations` (the file was written by a newer
// build; nothing may touch it). `path` is for the message only.
Status CheckKnown(int version, std::span<const Migration> migrations, const std::string& path);

// In one BEGIN IMMEDIATE transaction: re-reads the version (another process may have migrated meanwhile),
// refuses a newer one, applies every migration above it and sets user_version. On any error nothing is
// changed. Returns the version afterwards.
StatusOr<int> Migrate(sql::Connection* conn, std::span<const Migration> migrations, const std::string& path);

}  // namespace vb::db::schema
