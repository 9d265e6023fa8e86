#include "db/pg_copy.h"

#include <sqlite3.h>
#include <unistd.h>

#include <cmath>
#include <functional>
#include <memory>
#include <optional>

#include "db/open_store.h"
#include "db/pg_conn.h"
#include "db/pg_schema.h"
#include "db/pg_store.h"
#include "db/schema.h"
#include "db/sqlite_conn.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/text.h"

namespace vb::db {
namespace {

// How a column travels: its SQLite value as the PostgreSQL parameter of the column's type.
enum class Kind { kInt, kIntOrNull, kBool, kDouble, kDoubleOrNull, kText, kTextOrNull, kBlob };
struct Column {
  const char* name;
  Kind kind;
};
struct Table {
  const char* name;
  const char* order;  // ORDER BY of the SQLite read (rowid order keeps run_tags' submission order)
  std::vector<Column> columns;
  const char* identity = nullptr;  // id column whose sequence moves past the copied ids
};

// Every table of the SQLite schema (db/schema.cc, versions 1..7) with history worth moving, parents first. The
// lab's runtime tables (hosts, stale_writes, nights_claimed) are not copied: they describe a lab's live hosts.
std::vector<Table> Tables() {
  using K = Kind;
  return {
      {"batches",
       "id",
       {{"id", K::kInt}, {"submitter", K::kText}, {"name", K::kText}, {"spec_json", K::kText}, {"created", K::kDouble}},
       "id"},
      {"runs",
       "id",
       {{"id", K::kInt},
        {"batch_id", K::kInt},
        {"name", K::kText},
        {"controller", K::kText},
        {"bench_kind", K::kText},
        {"requested_bench", K::kText},
        {"bench_name", K::kText},
        {"spec_json", K::kText},
        {"submitter", K::kText},
        {"priority", K::kInt},
        {"status", K::kText},
        {"reason", K::kText},
        {"requeue_on_interrupt", K::kBool},
        {"cancel_requested", K::kBool},
        {"submitted", K::kDouble},
        {"started", K::kDouble},
        {"finished", K::kDouble},
        {"progress", K::kDouble},
        {"key_name", K::kText},
        {"repeat_index", K::kInt},
        {"split", K::kText},
        {"t_start_s", K::kDoubleOrNull},
        {"exec_wall_s", K::kDoubleOrNull},
        {"exec_simulated_s", K::kDoubleOrNull},
        {"exec_samples", K::kIntOrNull},
        {"exec_control_ticks", K::kIntOrNull},
        {"exec_metrics_from_trajectory", K::kIntOrNull},
        {"loop_ticks", K::kIntOrNull},
        {"loop_overruns", K::kIntOrNull},
        {"loop_jitter_p50_s", K::kDoubleOrNull},
        {"loop_jitter_p99_s", K::kDoubleOrNull},
        {"loop_jitter_max_s", K::kDoubleOrNull},
        {"exec_build", K::kTextOrNull}},
       "id"},
      {"run_tags", "rowid", {{"run_id", K::kInt}, {"tag", K::kText}}},
      {"run_sweep",
       "run_id, axis",
       {{"run_id", K::kInt}, {"axis", K::kInt}, {"field", K::kText}, {"value", K::kDouble}}},
      {"status_history",
       "id",
       {{"id", K::kInt}, {"run_id", K::kInt}, {"status", K::kText}, {"at", K::kDouble}, {"reason", K::kText}},
       "id"},
      {"metrics", "run_id, name", {{"run_id", K::kInt}, {"name", K::kText}, {"value", K::kDoubleOrNull}}},
      {"trace_chunks",
       "run_id, idx",
       {{"run_id", K::kInt},
        {"idx", K::kInt},
        {"t0", K::kDouble},
        {"period", K::kDouble},
        {"samples", K::kInt},
        {"channels", K::kText},
        {"data", K::kBlob},
        {"codec", K::kInt}}},
      {"baselines",
       "id",
       {{"id", K::kInt},
        {"name", K::kText},
        {"version", K::kInt},
        {"created", K::kDouble},
        {"source", K::kText},
        {"note", K::kText}},
       "id"},
      {"baseline_metrics",
       "baseline_id, case_name, metric",
       {{"baseline_id", K::kInt},
        {"case_name", K::kText},
        {"metric", K::kText},
        {"mean", K::kDouble},
        {"spread", K::kDouble},
        {"n", K::kInt}}},
      {"regressions",
       "id",
       {{"id", K::kInt},
        {"suite", K::kText},
        {"baseline_name", K::kText},
        {"baseline_version", K::kInt},
        {"batch_id", K::kInt},
        {"night", K::kText},
        {"created", K::kDouble},
        {"verdict", K::kText},
        {"result_json", K::kText}},
       "id"},
  };
}

// A read-only SQLite handle for the copy (the store has migrated the file before).
class SqliteReader {
 public:
  ~SqliteReader() {
    if (db_ != nullptr) sqlite3_close(db_);
  }
  Status Open(const std::string& path) {
    if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
      return Status::Unavailable(Cat("database '", path, "': cannot open: ", db_ ? sqlite3_errmsg(db_) : "?"));
    }
    sqlite3_busy_timeout(db_, 5000);
    return Status::Ok();
  }
  // Runs `sql`, calling fn(stmt) per row.
  Status ForEach(const std::string& sql, const std::function<Status(sqlite3_stmt*)>& fn) {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) {
      return Status::Internal(Cat("\"", sql, "\": ", sqlite3_errmsg(db_)));
    }
    Status out;
    while (true) {
      const int rc = sqlite3_step(st);
      if (rc == SQLITE_DONE) break;
      if (rc != SQLITE_ROW) {
        out = Status::Unavailable(Cat("\"", sql, "\": ", sqlite3_errmsg(db_)));
        break;
      }
      out = fn(st);
      if (!out.ok()) break;
    }
    sqlite3_finalize(st);
    return out;
  }
  StatusOr<std::int64_t> Int(const std::string& sql) {
    std::int64_t v = 0;
    VB_RETURN_IF_ERROR(ForEach(sql, [&](sqlite3_stmt* st) {
      v = sqlite3_column_int64(st, 0);
      return Status::Ok();
    }));
    return v;
  }
  sqlite3* raw() { return db_; }

 private:
  sqlite3* db_ = nullptr;
};

}  // namespace

StatusOr<CopySummary> CopySqliteToPostgres(const std::string& sqlite_path, const std::string& pg_location,
                                           const CopyOptions& options) {
  if (sqlite_path.empty()) return Status::InvalidArgument("--from: must name a SQLite store file");
  if (pg::IsPostgresLocation(sqlite_path)) {
    return Status::InvalidArgument("--from: must be a SQLite store file, got a PostgreSQL connection string");
  }
  if (!pg::IsPostgresLocation(pg_location)) {
    return Status::InvalidArgument(
        Cat("--to: must be a PostgreSQL connection string (postgresql://... or "
            "\"host=... dbname=...\"), got \"",
            pg_location, "\""));
  }
  if (access(sqlite_path.c_str(), R_OK) != 0) {
    return Status::NotFound(Cat("--from: no SQLite store at '", sqlite_path, "'"));
  }
  CopySummary summary;
  {
    // Opening brings an older file to the current schema (what any valvebench command does to it).
    auto source = OpenSqliteStore(sqlite_path);
    if (!source.ok()) return source.status();
    summary.source_version = (*source)->schema_version();
  }
  SqliteReader src;
  VB_RETURN_IF_ERROR(src.Open(sqlite_path));
  VB_ASSIGN_OR_RETURN(const std::int64_t running, src.Int("SELECT count(*) FROM runs WHERE status = 'running'"));
  if (running > 0) {
    return Status::FailedPrecondition(Cat("--from: ", running, " runs in '", sqlite_path,
                                          "' are running: stop the "
                                          "server that uses it, then copy (its next start would re-queue them)"));
  }

  {
    auto target = OpenPgStore(pg_location);  // creates or checks the PostgreSQL schema
    if (!target.ok()) return target.status();
    summary.target_version = (*target)->schema_version();
  }
  VB_ASSIGN_OR_RETURN(std::unique_ptr<pg::Connection> dst, pg::Connection::Open(pg_location));
  pg::Transaction txn(dst.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  // Nobody else writes while the ids are decided: the copy takes the tables it fills.
  VB_RETURN_IF_ERROR(dst->Script("LOCK TABLE batches, runs, status_history, baselines, regressions IN EXCLUSIVE MODE"));
  if (!options.into_non_empty) {
    VB_ASSIGN_OR_RETURN(const std::int64_t held,
                           dst->QueryInt("SELECT (SELECT count(*) FROM runs) + (SELECT count(*) FROM batches) + "
                                         "(SELECT count(*) FROM baselines) + (SELECT count(*) FROM regressions)"));
    if (held > 0) {
      return Status::FailedPrecondition(Cat("--to: ", dst->location(), " already holds ", held,
                                            " runs, batches, "
                                            "baselines or regression results; nothing was copied (--into-non-empty "
                                            "to add to it, when no id collides)"));
    }
  }

  for (const Table& t : Tables()) {
    std::string cols, params;
    for (std::size_t k = 0; k < t.columns.size(); ++k) {
      cols += Cat(k ? ", " : "", t.columns[k].name);
      params += Cat(k ? ", $" : "$", k + 1);
    }
    // Explicit ids go into identity columns as they are (GENERATED BY DEFAULT), run_tags' own id is generated.
    const std::string insert = Cat("INSERT INTO ", t.name, " (", cols, ") VALUES (", params, ")");
    std::int64_t rows = 0;
    Status st = src.ForEach(Cat("SELECT ", cols, " FROM ", t.name, " ORDER BY ", t.order), [&](sqlite3_stmt* row) {
      pg::Params p;
      for (std::size_t k = 0; k < t.columns.size(); ++k) {
        const int c = static_cast<int>(k);
        const bool null = sqlite3_column_type(row, c) == SQLITE_NULL;
        switch (t.columns[k].kind) {
          case Kind::kInt:
            p.Int(sqlite3_column_int64(row, c));
            break;
          case Kind::kIntOrNull:
            if (null)
              p.IntOrNull(std::nullopt);
            else
              p.IntOrNull(sqlite3_column_int64(row, c));
            break;
          case Kind::kBool:
            p.Bool(sqlite3_column_int64(row, c) != 0);
            break;
          case Kind::kDouble:
            p.Double(sqlite3_column_double(row, c));
            break;
          case Kind::kDoubleOrNull:
            p.DoubleOrNull(null ? std::nan("") : sqlite3_column_double(row, c));
            break;
          case Kind::kText: {
            const auto* s = reinterpret_cast<const char*>(sqlite3_column_text(row, c));
            p.Text(std::string_view(s != nullptr ? s : "", static_cast<std::size_t>(sqlite3_column_bytes(row, c))));
            break;
          }
          case Kind::kTextOrNull: {
            const auto* s = reinterpret_cast<const char*>(sqlite3_column_text(row, c));
            if (null || s == nullptr)
              p.TextOrNull(std::nullopt);
            else
              p.Text(std::string_view(s, static_cast<std::size_t>(sqlite3_column_bytes(row, c))));
            break;
          }
          case Kind::kBlob: {
            const void* b = sqlite3_column_blob(row, c);
            const int n = sqlite3_column_bytes(row, c);
            p.Bytes(b, static_cast<std::size_t>(n));
            summary.trace_bytes += n;
            break;
          }
        }
      }
      ++rows;
      return dst->Exec(insert, p).status().WithContext(Cat("copying ", t.name, " row ", rows));
    });
    VB_RETURN_IF_ERROR(st);
    summary.rows.emplace_back(t.name, rows);
    if (t.identity != nullptr) {
      VB_RETURN_IF_ERROR(dst->Exec(Cat("SELECT setval(pg_get_serial_sequence('", t.name, "', '", t.identity,
                                       "'), "
                                       "max(",
                                       t.identity, ")) FROM ", t.name, " HAVING count(*) > 0"))
                             .status());
    }
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return summary;
}

StatusOr<StoreInfo> ReadStoreInfo(const std::string& location) {
  StoreInfo info;
  const bool postgres = pg::IsPostgresLocation(location);
  if (!postgres && location != ":memory:" && access(location.c_str(), F_OK) != 0) {
    return Status::NotFound(Cat("--db: no store at '", location, "'"));
  }
  auto store = OpenStore(location);
  if (!store.ok()) return store.status();
  info.engine = postgres ? "postgresql" : "sqlite";
  info.location = postgres ? pg::DescribeLocation(location) : location;
  info.schema_version = (*store)->schema_version();
  std::unique_ptr<pg::Connection> pgc;
  std::optional<sql::Connection> lite;
  if (postgres) {
    VB_ASSIGN_OR_RETURN(pgc, pg::Connection::Open(location));
  } else {
    auto c = sql::Connection::Open(location);
    if (!c.ok()) return c.status();
    lite.emplace(std::move(c).value());
  }
  auto count = [&](const std::string& sql) -> StatusOr<std::int64_t> {
    return postgres ? pgc->QueryInt(sql) : lite->QueryInt(sql);
  };
  for (RunStatus s : {RunStatus::kQueued, RunStatus::kRunning, RunStatus::kDone, RunStatus::kFailed,
                      RunStatus::kCancelled, RunStatus::kInterrupted}) {
    VB_ASSIGN_OR_RETURN(const std::int64_t n,
                           count(Cat("SELECT count(*) FROM runs WHERE status = '", RunStatusName(s), "'")));
    info.runs_by_status.emplace_back(std::string(RunStatusName(s)), n);
  }
  for (const char* table :
       {"batches", "runs", "status_history", "metrics", "trace_chunks", "baselines", "regressions"}) {
    VB_ASSIGN_OR_RETURN(const std::int64_t n, count(Cat("SELECT count(*) FROM ", table)));
    info.rows.emplace_back(table, n);
  }
  VB_ASSIGN_OR_RETURN(info.trace_bytes,
                         count(postgres ? "SELECT COALESCE(SUM(octet_length(data)), 0)::int8 FROM trace_chunks"
                                        : "SELECT COALESCE(SUM(length(data)), 0) FROM trace_chunks"));
  return info;
}

}  // namespace vb::db
