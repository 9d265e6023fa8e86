#include "db/open_store.h"

#include "db/pg_conn.h"
#include "db/pg_store.h"
#include "db/sqlite_store.h"

namespace vb::db {

bool IsPostgresLocation(const std::string& location) { return pg::IsPostgresLocation(location); }

std::string DisplayLocation(const std::string& location) {
  return pg::IsPostgresLocation(location) ? pg::DescribeLocation(location) : location;
}

StatusOr<std::unique_ptr<Store>> OpenStore(const std::string& location) {
  if (pg::IsPostgresLocation(location)) return OpenPgStore(location);
  return OpenSqliteStore(location);
}

}  // namespace vb::db
