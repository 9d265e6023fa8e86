// Administering a store as a whole, below any service (benchctl db info, db copy; docs/store.md): these open a
// store file or database themselves, so they work with no server running and on a store nobody serves. They
// are here, not in benchctl, so that benchctl holds no store code (issue 27); the types are the service's, the
// work is db/pg_copy.h's.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "common/status.h"

namespace vb::server {

struct StoreSummary {
  std::string engine;    // "sqlite" | "postgresql"
  std::string location;  // the file, or the PostgreSQL database without its password
  int schema_version = 0;
  std::vector<std::pair<std::string, std::int64_t>> runs_by_status;  // every status, in lifecycle order
  std::vector<std::pair<std::string, std::int64_t>> rows;            // batches, runs, trace_chunks, baselines, ...
  std::int64_t trace_bytes = 0;                                      // as stored (compressed)
};
// Opens the store at `location` (migrating an older schema, as every open does) and counts.
StatusOr<StoreSummary> DescribeStore(const std::string& location);

struct StoreCopy {
  std::vector<std::pair<std::string, std::int64_t>> rows;  // per table, in copy order
  std::int64_t trace_bytes = 0;
  int source_version = 0, target_version = 0;
};
// Every row of the SQLite store at sqlite_path into the PostgreSQL store at pg_location, ids kept, in one
// transaction; a target holding runs is refused unless into_non_empty (db::CopySqliteToPostgres).
StatusOr<StoreCopy> CopyStoreToPostgres(const std::string& sqlite_path, const std::string& pg_location,
                                        bool into_non_empty);

}  // namespace vb::server
