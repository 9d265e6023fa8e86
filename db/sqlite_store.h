// The SQLite engine of the results store (db/store.h; docs/store.md): one database file on one machine, shared
// by every Store opened on it (threads, processes: WAL). The engine's class is private to db/sqlite_store.cc;
// callers hold it as a Store. db/open_store.h picks this engine or PostgreSQL's by location.
#pragma once

#include <memory>
#include <string>

#include "common/status.h"
#include "db/store.h"

namespace vb::db {

// Opens (creating if needed) the database at path, with WAL, foreign keys and busy timeout on, and migrates
// the schema to the current version. ":memory:" works for tests.
StatusOr<std::unique_ptr<Store>> OpenSqliteStore(const std::string& path);

}  // namespace vb::db
