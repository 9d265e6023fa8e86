// Listing runs (docs/store.md, "Listing runs"): the order (AIP-132 order_by), the keyset cursor that pages through
// any order, the opaque page token that carries it, and the one SQL text of a RunFilter that both engines run
// (SQLite db/sqlite_store.cc, PostgreSQL db/pg_store.cc differ only in placeholders and collation).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "common/status.h"
#include "db/records.h"

namespace vb::db {

// "FIELD" or "FIELD desc" (AIP-132); "" = the API's default, "submitted desc". InvalidArgument naming `order_by`
// and listing the fields otherwise.
StatusOr<RunOrder> ParseRunOrder(std::string_view order_by);
// The text ParseRunOrder reads back: "submitted desc", "name".
std::string RunOrderText(const RunOrder& order);
// The field names in the order the error message lists them.
const std::vector<std::string_view>& RunSortFields();

// The cursor just after `run` in `order`: its sort key's value (as the SQL computes it) and its id.
RunCursor CursorAfter(const RunRecord& run, const RunOrder& order);

// Page tokens: opaque text carrying the cursor and a fingerprint of the filters and order it was made for. A
// token decoded with other filters or another order is refused (InvalidArgument naming page_token), so a client
// cannot mix pages of two listings. The page size may change between pages.
std::string EncodePageToken(const RunFilter& filter, const RunRecord& last);
// Sets filter->after from `token` ("" = the first page: nothing to do).
Status ApplyPageToken(std::string_view token, RunFilter* filter);

namespace run_query {

// A bound value of a built query, in placeholder order.
using Param = std::variant<std::int64_t, double, std::string>;

enum class Dialect { kSqlite, kPostgres };

struct Query {
  std::string sql;            // " FROM runs WHERE ... [ORDER BY ... LIMIT n]", after the engine's SELECT list
  std::vector<Param> params;  // ?1.. (SQLite) or $1.. (PostgreSQL), in order
};

// The rows of ListRuns(filter): its filters, its cursor, its order and its limit.
Query Page(const RunFilter& filter, Dialect dialect);
// How many runs match the filter (the cursor and the limit ignored): "SELECT count(*)" + sql.
Query Count(const RunFilter& filter, Dialect dialect);

}  // namespace run_query
}  // namespace vb::db
