#include "service/store_admin.h"

#include "db/pg_copy.h"

namespace vb::server {

StatusOr<StoreSummary> DescribeStore(const std::string& location) {
  auto info = db::ReadStoreInfo(location);
  if (!info.ok()) return info.status();
  return StoreSummary{info->engine, info->location, info->schema_version, info->runs_by_status, info->rows,
                      info->trace_bytes};
}

StatusOr<StoreCopy> CopyStoreToPostgres(const std::string& sqlite_path, const std::string& pg_location,
                                        bool into_non_empty) {
  auto s = db::CopySqliteToPostgres(sqlite_path, pg_location, {into_non_empty});
  if (!s.ok()) return s.status();
  return StoreCopy{s->rows, s->trace_bytes, s->source_version, s->target_version};
}

}  // namespace vb::server
