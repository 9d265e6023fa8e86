#include "db/regress_tables.h"

#include <cmath>
#include <set>
#include <utility>

#include "db/text.h"

namespace vb::db::regress_tables {

using sql::Stmt;

// The tables themselves are created by migration 2 (db/schema.cc).



StatusOr<int> InsertBaseline(sql::Connection* conn, const std::string& name, const std::string& source,
                             const std::string& note, const std::vector<BaselineEntry>& entries, double now) {
  VB_ASSIGN_OR_RETURN(Stmt last, conn->Prepare("SELECT COALESCE(MAX(version), 0) FROM baselines WHERE name = ?1"));
  last.Bind(1, name);
  VB_ASSIGN_OR_RETURN(const bool row, last.Step());
  const int version = row ? static_cast<int>(last.Int(0)) + 1 : 1;
  VB_ASSIGN_OR_RETURN(Stmt ins, conn->Prepare("INSERT INTO baselines (name, version, created, source, note) "
                                                 "VALUES (?1, ?2, ?3, ?4, ?5)"));
  ins.Bind(1, name);
  ins.Bind(2, version);
  ins.Bind(3, now);
  ins.Bind(4, source);
  ins.Bind(5, note);
  VB_RETURN_IF_ERROR(ins.Run());
  const std::int64_t id = sqlite3_last_insert_rowid(conn->raw());
  for (const BaselineEntry& e : entries) {
    VB_ASSIGN_OR_RETURN(Stmt m, conn->Prepare("INSERT INTO baseline_metrics (baseline_id, case_name, metric, mean, "
                                                 "spread, n) VALUES (?1, ?2, ?3, ?4, ?5, ?6)"));
    m.Bind(1, id);
    m.Bind(2, e.case_name);
    m.Bind(3, e.metric);
    m.Bind(4, e.mean);
    m.Bind(5, e.spread);
    m.Bind(6, static_cast<std::int64_t>(e.n));
    VB_RETURN_IF_ERROR(m.Run());
  }
  return version;
}

StatusOr<BaselineRecord> LoadBaseline(sql::Connection* conn, const std::string& name, int version) {
  if (version < 0) return Status::InvalidArgument(Cat("version: must be >= 1 (0 = newest), got ", version));
  VB_ASSIGN_OR_RETURN(
      Stmt st, conn->Prepare(version == 0 ? "SELECT id, version, created, source, note FROM baselines WHERE name = ?1 "
                                            "ORDER BY version DESC LIMIT 1"
                                          : "SELECT id, version, created, source, note FROM baselines WHERE name = ?1 "
                                            "AND version = ?2"));
  st.Bind(1, name);
  if (version != 0) st.Bind(2, version);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) {
    return Status::NotFound(version == 0 ? Cat("baseline '", name, "' not found")
                                         : Cat("baseline '", name, "' has no version ", version));
  }
  BaselineRecord b;
  const std::int64_t id = st.Int(0);
  b.name = name;
  b.version = static_cast<std::int32_t>(st.Int(1));
  b.created_unix_s = st.Double(2);
  b.source = st.Text(3);
  b.note = st.Text(4);
  VB_ASSIGN_OR_RETURN(Stmt m, conn->Prepare("SELECT case_name, metric, mean, spread, n FROM baseline_metrics "
                                               "WHERE baseline_id = ?1 ORDER BY case_name, metric"));
  m.Bind(1, id);
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool more, m.Step());
    if (!more) break;
    b.entries.push_back({m.Text(0), m.Text(1), m.Double(2), m.Double(3), static_cast<std::int32_t>(m.Int(4))});
  }
  return b;
}

StatusOr<std::vector<BaselineRecord>> ListBaselines(sql::Connection* conn) {
  VB_ASSIGN_OR_RETURN(
      Stmt st, conn->Prepare("SELECT name, version, created, source, note FROM baselines ORDER BY name, version"));
  std::vector<BaselineRecord> out;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    BaselineRecord b;
    b.name = st.Text(0);
    b.version = static_cast<std::int32_t>(st.Int(1));
    b.created_unix_s = st.Double(2);
    b.source = st.Text(3);
    b.note = st.Text(4);
    out.push_back(std::move(b));
  }
  return out;
}

StatusOr<std::int64_t> InsertRegression(sql::Connection* conn, const RegressionRecord& r, double now) {
  VB_ASSIGN_OR_RETURN(Stmt st, conn->Prepare("INSERT INTO regressions (suite, baseline_name, baseline_version, "
                                                "batch_id, night, created, verdict, result_json) VALUES "
                                                "(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)"));
  st.Bind(1, r.suite);
  st.Bind(2, r.baseline_name);
  st.Bind(3, static_cast<std::int64_t>(r.baseline_version));
  st.Bind(4, r.batch_id);
  st.Bind(5, r.night);
  st.Bind(6, r.created_unix_s > 0 ? r.created_unix_s : now);
  st.Bind(7, r.verdict);
  st.Bind(8, r.result_json);
  VB_RETURN_IF_ERROR(st.Run());
  return static_cast<std::int64_t>(sqlite3_last_insert_rowid(conn->raw()));
}

namespace {
constexpr const char* kRegressionColumns =
    "id, suite, baseline_name, baseline_version, batch_id, night, created, verdict";
RegressionRecord ReadRegression(const Stmt& st) {
  RegressionRecord r;
  r.id = st.Int(0);
  r.suite = st.Text(1);
  r.baseline_name = st.Text(2);
  r.baseline_version = static_cast<std::int32_t>(st.Int(3));
  r.batch_id = st.Int(4);
  r.night = st.Text(5);
  r.created_unix_s = st.Double(6);
  r.verdict = st.Text(7);
  return r;
}
}  // namespace

StatusOr<RegressionRecord> LoadRegression(sql::Connection* conn, std::int64_t id) {
  VB_ASSIGN_OR_RETURN(Stmt st, conn->Prepare(Cat("SELECT ", kRegressionColumns,
                                                    ", result_json FROM regressions WHERE id = ?1")));
  st.Bind(1, id);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return Status::NotFound(Cat("regression ", id, " not found"));
  RegressionRecord r = ReadRegression(st);
  r.result_json = st.Text(8);
  return r;
}

StatusOr<std::vector<RegressionRecord>> ListRegressions(sql::Connection* conn, bool nights_only, int limit) {
  VB_ASSIGN_OR_RETURN(
      Stmt st, conn->Prepare(Cat("SELECT ", kRegressionColumns, " FROM regressions",
                                 nights_only ? " WHERE night != ''" : "", " ORDER BY id DESC LIMIT ?1")));
  st.Bind(1, static_cast<std::int64_t>(limit));
  std::vector<RegressionRecord> out;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    out.push_back(ReadRegression(st));
  }
  return out;
}

}  // namespace vb::db::regress_tables
