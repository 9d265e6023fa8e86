// The PostgreSQL implementation of db/store.h (docs/store.md, "PostgreSQL"): one database shared by every host
// of a lab. Same methods, semantics and field-named errors as the SQLite store; differences (the clock, the
// queue's locking) are in docs/store.md.
#pragma once

#include <memory>
#include <string>

#include "common/status.h"
#include "db/store.h"

namespace vb::db {

// Connects to `location` (a postgresql:// or postgres:// URI, or a libpq keyword string such as
// "host=/run/postgresql dbname=lab") and migrates its schema to the current version (pg_schema.h).
// Unavailable when the server cannot be reached; FailedPrecondition for a newer schema or a foreign database.
StatusOr<std::unique_ptr<Store>> OpenPgStore(const std::string& location);

}  // namespace vb::db
