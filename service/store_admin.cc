#include "service/store_admin.h"

namespace vb::server {

StatusOr<StoreCopy> CopyStoreToPostgres(const std::string& sqlite_path, const std::string& pg_location,
                                        bool into_non_empty) {
  return db::CopySqliteToPostgres(sqlite_path, pg_location, {into_non_empty});
}

}  // namespace vb::server
