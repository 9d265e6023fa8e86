// Moving a SQLite store's history into PostgreSQL (benchctl db copy), and what a store holds (benchctl db info).
// docs/store.md, "PostgreSQL", "Moving a store".
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "common/status.h"

namespace vb::db {

struct CopyOptions {
  bool into_non_empty = false;  // copy into a target that already holds runs (ids must not collide)
};

struct CopySummary {
  std::vector<std::pair<std::string, std::int64_t>> rows;  // per table, in copy order
  std::int64_t trace_bytes = 0;                            // trace chunk bytes as stored (compressed)
  int source_version = 0, target_version = 0;
};

// Copies every row of the SQLite store at `sqlite_path` (migrated to the current version first, as any open
// does) into the PostgreSQL store at `pg_location`, in one PostgreSQL transaction: batches, runs, their status
// history, metrics, tags, sweep points, trace chunks exactly as stored (codec and bytes), baselines with their
// metrics, regression results; ids are kept and the id sequences moved past them. Refuses (FailedPrecondition,
// nothing written) a target that holds runs, batches, baselines or regressions unless
// options.into_non_empty, and a source with running runs (stop its server first). On any error nothing is
// copied.
StatusOr<CopySummary> CopySqliteToPostgres(const std::string& sqlite_path, const std::string& pg_location,
                                           const CopyOptions& options);

struct StoreInfo {
  std::string engine;    // "sqlite" | "postgresql"
  std::string location;  // the file, or the PostgreSQL database without its password
  int schema_version = 0;
  std::vector<std::pair<std::string, std::int64_t>> runs_by_status;  // every status, in lifecycle order
  std::vector<std::pair<std::string, std::int64_t>> rows;            // batches, runs, trace_chunks, baselines, ...
  std::int64_t trace_bytes = 0;
};

// Opens the store at `location` (OpenStore's rules: migrates an older schema, creates an empty one) and counts.
StatusOr<StoreInfo> ReadStoreInfo(const std::string& location);

}  // namespace vb::db
