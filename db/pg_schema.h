// The PostgreSQL store's schema and its migrations (docs/store.md, "PostgreSQL"). The version lives in the
// one-row table schema_version; migration N takes a database from version N-1 to N. Migrate() applies the
// missing ones in one transaction holding an advisory lock, so hosts of a lab starting at once take turns and
// the second one finds the work done.
//
// PostgreSQL databases start at version 5 (what SQLite's schema v5 holds): there are no older PostgreSQL
// databases to carry forward, so migration 5 creates the whole schema and versions 1..4 are empty steps that
// keep the numbering of db/schema.cc. Internal to db/; exposed so tests can exercise the machinery.
#pragma once

#include <span>
#include <string>

#include "common/status.h"
#include "db/pg_conn.h"

namespace vb::db::pg_schema {

struct Migration {
  int version;              // the version after this step: 1, 2, ... with no gaps
  const char* description;  // one line, for docs and errors
  const char* sql;          // one or more statements ("" = nothing to do)
};

std::span<const Migration> Migrations();
int CurrentVersion();

// The database's version: 0 for a database without valvebench's tables. Reads only.
StatusOr<int> ReadVersion(pg::Connection* conn);

// In one transaction under pg_advisory_xact_lock: re-reads the version, refuses a newer one (FailedPrecondition,
// nothing touched) and a database that has tables but no schema_version (somebody else's), applies every
// migration above the version and records it. On any error nothing is changed. Returns the version afterwards.
StatusOr<int> Migrate(pg::Connection* conn, std::span<const Migration> migrations);

}  // namespace vb::db::pg_schema
