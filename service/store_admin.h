// Copying a store as a whole, below any service (benchctl db copy; docs/store.md, "Moving a store"): it opens a
// SQLite file and a PostgreSQL database itself, so it works with no server running and on stores nobody serves.
// It is here, not in benchctl, so that benchctl holds no store code (issue 27). What a store holds (db info) is
// the service's DescribeStore RPC (service/records_service.cc), asked of the server or of the local service.
#pragma once

#include <string>

#include "common/status.h"
#include "db/pg_copy.h"

namespace vb::server {

// db/'s own summary (rows per table, trace bytes, schema versions), not a copy of it field by field: a plain
// value with no database behind it, which benchctl only prints.
using StoreCopy = db::CopySummary;

// Every row of the SQLite store at sqlite_path into the PostgreSQL store at pg_location, ids kept, in one
// transaction; a target holding runs is refused unless into_non_empty (db::CopySqliteToPostgres).
StatusOr<StoreCopy> CopyStoreToPostgres(const std::string& sqlite_path, const std::string& pg_location,
                                        bool into_non_empty);

}  // namespace vb::server
