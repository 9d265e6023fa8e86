// One way to open the store wherever it lives (docs/store.md, "PostgreSQL"): a PostgreSQL connection string
// (postgresql://..., postgres://..., or a libpq keyword string such as "host=/run/postgresql dbname=lab") opens
// the PostgreSQL store shared by a lab's hosts; anything else is a SQLite file path (or ":memory:").
#pragma once

#include <memory>
#include <string>

#include "common/status.h"
#include "db/store.h"

namespace vb::db {

StatusOr<std::unique_ptr<Store>> OpenStore(const std::string& location);
// True when OpenStore would open `location` on PostgreSQL.
bool IsPostgresLocation(const std::string& location);
// `location` for logs and messages: a file path as it is, a PostgreSQL database as host, port, database and user
// (never its password).
std::string DisplayLocation(const std::string& location);

}  // namespace vb::db
