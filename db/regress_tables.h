// Baselines and regression results in the store (schema v2; docs/store.md, docs/regress.md). Internal to db/:
// SqliteStore's methods call these inside their own transaction.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/status.h"
#include "db/records.h"
#include "db/sqlite_conn.h"

namespace vb::db::regress_tables {

StatusOr<int> InsertBaseline(sql::Connection* conn, const std::string& name, const std::string& source,
                             const std::string& note, const std::vector<BaselineEntry>& entries, double now);
StatusOr<BaselineRecord> LoadBaseline(sql::Connection* conn, const std::string& name, int version);
StatusOr<std::vector<BaselineRecord>> ListBaselines(sql::Connection* conn);

StatusOr<std::int64_t> InsertRegression(sql::Connection* conn, const RegressionRecord& r, double now);
StatusOr<RegressionRecord> LoadRegression(sql::Connection* conn, std::int64_t id);
StatusOr<std::vector<RegressionRecord>> ListRegressions(sql::Connection* conn, bool nights_only, int limit);

}  // namespace vb::db::regress_tables
