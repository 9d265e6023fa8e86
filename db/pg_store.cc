// The PostgreSQL implementation of db/store.h (docs/store.md, "PostgreSQL"). It mirrors the SQLite store
// (db/sqlite_store.cc) method by method: the same checks in the same order with the same field-named messages, the
// same rows. What differs is how concurrency is had: SQLite serialises writers with one lock, here many hosts
// write at once, so the queue is claimed with FOR UPDATE SKIP LOCKED and every write for a claimed run locks the
// run's row and checks its lease's fence in the same transaction. Times come from the database's clock.
#include "db/checks.h"
#include "db/pg_store.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <set>
#include <string_view>
#include <unordered_set>
#include <utility>
#include <variant>

#include "common/format.h"
#include "db/pg_conn.h"
#include "db/pg_schema.h"
#include "db/prune_plan.h"
#include "db/run_query.h"
#include "db/run_rules.h"
#include "db/text.h"
#include "db/trace_codec.h"

namespace vb::db {
namespace {

using pg::Params;
using pg::Result;
using TxnKind = pg::Transaction::Kind;

// The database's clock in unix seconds: the transaction's start (now()), so every row one method writes has the
// same time, whichever host's clock is off (docs/store.md, "PostgreSQL", "The clock").
#define VB_PG_NOW "extract(epoch FROM now())::float8"

// bytea values are limited to 1 GiB by PostgreSQL.
constexpr std::uint64_t kMaxBlobBytes = (std::uint64_t{1} << 30) - 1;

// The columns every RunRecord query reads (ReadRun() reads them in this order), tags and sweep point included as
// length-prefixed text so a listing is one query: tags as "<bytes>:<tag>", the sweep as "<bytes>:<field><value>;".
constexpr const char* kRunColumns =
    VB_DB_RUN_COLUMNS ", "
    "(SELECT string_agg(octet_length(t.tag) || ':' || t.tag, '' ORDER BY t.id) FROM run_tags t "
    "WHERE t.run_id = runs.id), "
    "(SELECT string_agg(octet_length(s.field) || ':' || s.field || s.value::text || ';', '' ORDER BY s.axis) "
    "FROM run_sweep s WHERE s.run_id = runs.id)";

using rules::RunNotFound;

// Parses "<n>:<n bytes>" items; `tail` (';' or 0) ends each item's remainder (the sweep value).
bool SplitPrefixed(std::string_view s, char tail, std::vector<std::pair<std::string, std::string>>* out) {
  while (!s.empty()) {
    const std::size_t colon = s.find(':');
    if (colon == std::string_view::npos) return false;
    const std::size_t n = std::strtoull(std::string(s.substr(0, colon)).c_str(), nullptr, 10);
    if (colon + 1 + n > s.size()) return false;
    std::string item(s.substr(colon + 1, n));
    s.remove_prefix(colon + 1 + n);
    std::string rest;
    if (tail != 0) {
      const std::size_t end = s.find(tail);
      if (end == std::string_view::npos) return false;
      rest = std::string(s.substr(0, end));
      s.remove_prefix(end + 1);
    }
    out->emplace_back(std::move(item), std::move(rest));
  }
  return true;
}



class PgStore final : public Store {
 public:
  PgStore(std::unique_ptr<pg::Connection> conn, int version) : conn_(std::move(conn)), version_(version) {}

  int schema_version() const override { return version_; }
  StatusOr<std::int64_t> SubmitBatch(const std::string& submitter, const std::string& name,
                                     const std::string& batch_spec_json, std::vector<RunRecord> runs,
                                     std::vector<std::int64_t>* run_ids) override;
  StatusOr<std::optional<RunRecord>> ClaimNext(const ClaimRequest& request) override;
  Status SetProgress(const Lease& lease, double progress) override;
  using Store::Finish;
  Status Finish(const Lease& lease, RunStatus final_status, const std::string& reason,
                const std::vector<Metric>& metrics, const std::optional<ExecutionRecord>& execution) override;
  StatusOr<RunStatus> RequestCancel(std::int64_t run_id, const std::string& reason) override;
  StatusOr<bool> CancelRequested(std::int64_t run_id) override;
  StatusOr<int> RecoverAfterCrash(const std::string& host) override { return RecoverAfterCrashAt(host, 0.0); }
  StatusOr<int> RecoverAfterCrashAt(const std::string& host, double stopped_unix_s) override;
  Status Heartbeat(const HostRecord& host, double lease_ttl_s, const std::vector<Lease>& executing) override;
  StatusOr<std::vector<HostRecord>> ListHosts() override;
  StatusOr<std::vector<std::int64_t>> RequeueLapsed() override;
  StatusOr<std::vector<StaleWrite>> StaleWrites(std::int32_t limit, std::int64_t* total) override;
  StatusOr<bool> ClaimNight(const std::string& night, const std::string& host) override;
  StatusOr<RunRecord> GetRun(std::int64_t run_id) override;
  StatusOr<std::vector<RunRecord>> ListRuns(const RunFilter& filter) override;
  StatusOr<std::int64_t> CountRuns(const RunFilter& filter) override;
  StatusOr<std::vector<StatusChange>> History(std::int64_t run_id) override;
  StatusOr<std::vector<Metric>> GetMetrics(std::int64_t run_id) override;
  StatusOr<std::int64_t> CountQueued(const std::string& submitter) override;
  StatusOr<std::int64_t> StoredTraceBytes(const std::string& submitter) override;
  Status AppendTraceChunk(const Lease& lease, const TraceChunk& chunk) override;
  StatusOr<std::vector<TraceChunk>> ReadTrace(std::int64_t run_id) override;
  Status ForEachTraceChunk(std::int64_t run_id,
                           const std::function<Status(const TraceChunk&, std::int64_t)>& fn) override;
  StatusOr<std::int32_t> SaveBaseline(const std::string& name, const std::string& source, const std::string& note,
                                      const std::vector<BaselineEntry>& entries) override;
  StatusOr<BaselineRecord> GetBaseline(const std::string& name, std::int32_t version) override;
  StatusOr<std::vector<BaselineRecord>> ListBaselines() override;
  StatusOr<std::int64_t> SaveRegression(const RegressionRecord& record) override;
  StatusOr<RegressionRecord> GetRegression(std::int64_t id) override;
  StatusOr<std::vector<RegressionRecord>> ListRegressions(bool nights_only, std::int32_t limit) override;
  StatusOr<PruneResult> Prune(const PruneRequest& request) override;

 private:
  StatusOr<RunStatus> StatusOf(std::int64_t run_id);
  Status AddHistory(std::int64_t run_id, RunStatus status, const std::string& reason);
  StatusOr<RunRecord> ReadRun(const Result& r, int row);
  StatusOr<RunRecord> LoadRun(std::int64_t run_id);
  // Locks the run's row and checks that `lease` holds it (rules::StaleWriteWhy: it is running and its fence is the
  // run's). A stale lease: the write is recorded in stale_writes, that is committed (ending `txn`) and
  // FailedPrecondition "stale write: ..." returned. NotFound for an unknown run.
  Status CheckLease(pg::Transaction* txn, const Lease& lease, const std::string& what);
  // Interrupts the selected running runs (RecoverAfterCrash, RequeueLapsed); returns their ids.
  // stopped_unix_s > 0: the interrupted entries carry it (when it is before the database's now) instead of now.
  StatusOr<std::vector<std::int64_t>> Interrupt(const std::string& select_sql, const Params& params, bool lapsed,
                                                double stopped_unix_s = 0.0);
  Status ReadChunks(std::int64_t run_id, const std::function<Status(TraceChunk&, std::int64_t)>& fn);

  std::unique_ptr<pg::Connection> conn_;
  int version_;
  trace::Codec1 codec_;
  std::string encoded_;
};

StatusOr<RunStatus> PgStore::StatusOf(std::int64_t run_id) {
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT status FROM runs WHERE id = $1", Params().Int(run_id)));
  if (r.rows() == 0) return RunNotFound(run_id);
  return rules::StoredStatus(r.Text(0, 0), Cat("run ", run_id));
}

Status PgStore::AddHistory(std::int64_t run_id, RunStatus status, const std::string& reason) {
  return conn_
      ->Exec("INSERT INTO status_history (run_id, status, at, reason) VALUES ($1, $2, " VB_PG_NOW ", $3)",
             Params().Int(run_id).Text(RunStatusName(status)).Text(reason))
      .status();
}

// One row of a Result as rules::RunFromRow reads it.
struct PgRow {
  const Result& r;
  int k;
  std::int64_t Int(int col) const { return r.Int(k, col); }
  std::string Text(int col) const { return r.Text(k, col); }
  double Double(int col) const { return r.Double(k, col); }
  bool IsNull(int col) const { return r.IsNull(k, col); }
};

StatusOr<RunRecord> PgStore::ReadRun(const Result& row, int k) {
  VB_ASSIGN_OR_RETURN(RunRecord r, rules::RunFromRow(PgRow{row, k}));
  std::vector<std::pair<std::string, std::string>> items;
  if (!SplitPrefixed(row.Text(k, rules::kRunColumnCount), 0, &items))
    return Status::DataLoss(Cat("run ", r.id, ": unreadable tags"));
  for (auto& [tag, _] : items) r.tags.push_back(std::move(tag));
  items.clear();
  if (!SplitPrefixed(row.Text(k, rules::kRunColumnCount + 1), ';', &items))
    return Status::DataLoss(Cat("run ", r.id, ": unreadable sweep"));
  for (auto& [field, value] : items) r.key.sweep.push_back({std::move(field), std::strtod(value.c_str(), nullptr)});
  return r;
}

StatusOr<RunRecord> PgStore::LoadRun(std::int64_t run_id) {
  static const std::string sql = Cat("SELECT ", kRunColumns, " FROM runs WHERE id = $1");
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec(sql, Params().Int(run_id)));
  if (r.rows() == 0) return RunNotFound(run_id);
  return ReadRun(r, 0);
}

// ---- Submission and the queue ----

StatusOr<std::int64_t> PgStore::SubmitBatch(const std::string& submitter, const std::string& name,
                                            const std::string& batch_spec_json, std::vector<RunRecord> runs,
                                            std::vector<std::int64_t>* run_ids) {
  VB_RETURN_IF_ERROR(checks::ValidateBatch(submitter, runs));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  VB_ASSIGN_OR_RETURN(
      const std::int64_t batch_id,
      conn_->QueryInt("INSERT INTO batches (submitter, name, spec_json, created) VALUES ($1, $2, $3, " VB_PG_NOW
                      ") RETURNING id",
                      Params().Text(submitter).Text(name).Text(batch_spec_json)));
  std::vector<std::int64_t> ids;
  ids.reserve(runs.size());
  for (const RunRecord& r : runs) {
    VB_ASSIGN_OR_RETURN(
        const std::int64_t id,
        conn_->QueryInt(
            "INSERT INTO runs (batch_id, name, controller, bench_kind, requested_bench, bench_name, "
            "spec_json, submitter, priority, status, requeue_on_interrupt, submitted, key_name, "
            "repeat_index, split, t_start_s) VALUES ($1, $2, $3, $4, $5, $5, $6, $7, $8, 'queued', $9, " VB_PG_NOW
            ", $10, $11, $12, $13) RETURNING id",
            Params()
                .Int(batch_id)
                .Text(r.key.DisplayName())
                .Text(r.controller)
                .Text(r.bench_kind)
                .Text(r.bench_name)
                .Text(r.spec_json)
                .Text(submitter)
                .Int(r.priority)
                .Bool(r.requeue_on_interrupt)
                .Text(r.key.name)
                .Int(r.key.repeat)
                .Text(r.split)
                .DoubleOrNull(r.t_start_s)));
    ids.push_back(id);
    for (std::size_t a = 0; a < r.key.sweep.size(); ++a) {
      VB_RETURN_IF_ERROR(conn_
                             ->Exec("INSERT INTO run_sweep (run_id, axis, field, value) VALUES ($1, $2, $3, $4)",
                                    Params()
                                        .Int(id)
                                        .Int(static_cast<std::int64_t>(a))
                                        .Text(r.key.sweep[a].field)
                                        .Double(r.key.sweep[a].value))
                             .status());
    }
    for (const std::string& tag : r.tags) {
      VB_RETURN_IF_ERROR(
          conn_->Exec("INSERT INTO run_tags (run_id, tag) VALUES ($1, $2)", Params().Int(id).Text(tag)).status());
    }
    VB_RETURN_IF_ERROR(AddHistory(id, RunStatus::kQueued, ""));
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  if (run_ids != nullptr) *run_ids = std::move(ids);
  return batch_id;
}

StatusOr<std::optional<RunRecord>> PgStore::ClaimNext(const ClaimRequest& request) {
  VB_RETURN_IF_ERROR(checks::CheckClaim(request));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  // The inner SELECT locks the first compatible queued run that no other claimer has locked (SKIP LOCKED): two
  // claimers never wait for each other and never get the same run; a run another claimer claimed and committed
  // meanwhile is re-checked against status = 'queued' and passed over.
  VB_ASSIGN_OR_RETURN(
      Result claimed,
      conn_->Exec("UPDATE runs SET status = 'running', bench_name = $2, host = $3, fence = fence + 1, "
                  "started = " VB_PG_NOW ", finished = 0, progress = 0, reason = '', cancel_requested = false, "
                  "lease_expires = CASE WHEN $4 > 0 THEN " VB_PG_NOW " + $4 ELSE 0 END "
                  "WHERE id = (SELECT id FROM runs WHERE status = 'queued' "
                  "AND (bench_kind = '' OR bench_kind = $1) AND (bench_name = '' OR bench_name = $2) "
                  "ORDER BY priority + CASE WHEN $5 > 0 THEN floor((" VB_PG_NOW " - submitted) / $5) ELSE 0 END "
                  "DESC, id LIMIT 1 FOR UPDATE SKIP LOCKED) RETURNING id",
                  Params()
                      .Text(request.bench_kind)
                      .Text(request.bench_name)
                      .Text(request.host)
                      .Double(request.lease_ttl_s)
                      .Double(request.aging_s)));
  if (claimed.rows() == 0) return std::optional<RunRecord>();  // the destructor rolls back the empty transaction
  const std::int64_t id = claimed.Int(0, 0);
  VB_RETURN_IF_ERROR(AddHistory(id, RunStatus::kRunning,
                                request.host.empty()
                                    ? Cat("claimed by bench ", request.bench_name)
                                    : Cat("claimed by bench ", request.bench_name, " on host ", request.host)));
  VB_ASSIGN_OR_RETURN(RunRecord run, LoadRun(id));
  VB_RETURN_IF_ERROR(txn.Commit());
  return std::optional<RunRecord>(std::move(run));
}

Status PgStore::CheckLease(pg::Transaction* txn, const Lease& lease, const std::string& what) {
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT status, fence, host FROM runs WHERE id = $1 FOR UPDATE",
                                               Params().Int(lease.run_id)));
  if (r.rows() == 0) return RunNotFound(lease.run_id);
  VB_ASSIGN_OR_RETURN(const RunStatus status, rules::StoredStatus(r.Text(0, 0), Cat("run ", lease.run_id)));
  const std::int64_t fence = r.Int(0, 1);
  const std::string host = r.Text(0, 2);
  std::optional<std::string> stale = rules::StaleWriteWhy(lease, what, status, fence, host);
  if (!stale) return Status::Ok();
  VB_RETURN_IF_ERROR(conn_
                         ->Exec("INSERT INTO stale_writes (run_id, fence, current_fence, host, what, at) "
                                "VALUES ($1, $2, $3, $4, $5, " VB_PG_NOW ")",
                                Params()
                                    .Int(lease.run_id)
                                    .Int(lease.fence)
                                    .Int(fence)
                                    .Text(status == RunStatus::kRunning ? host : std::string())
                                    .Text(what))
                         .status());
  VB_RETURN_IF_ERROR(txn->Commit());
  return Status::FailedPrecondition(std::move(*stale));
}

Status PgStore::SetProgress(const Lease& lease, double progress) {
  VB_RETURN_IF_ERROR(checks::CheckProgress(progress));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  VB_RETURN_IF_ERROR(CheckLease(&txn, lease, "progress"));
  VB_RETURN_IF_ERROR(
      conn_->Exec("UPDATE runs SET progress = $2 WHERE id = $1", Params().Int(lease.run_id).Double(progress)).status());
  return txn.Commit();
}

Status PgStore::Finish(const Lease& lease, RunStatus final_status, const std::string& reason,
                       const std::vector<Metric>& metrics, const std::optional<ExecutionRecord>& execution) {
  const std::int64_t run_id = lease.run_id;
  VB_RETURN_IF_ERROR(checks::CheckFinish(final_status, metrics));
  if (execution) VB_RETURN_IF_ERROR(checks::CheckExecution(*execution));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  {
    // A retry of a Finish whose COMMIT was sent but whose answer was lost (the connection dropped): if the run
    // is already in exactly the state this attempt writes, that first try committed. Nothing to do, and not a
    // stale write (docs/lab.md, "When the database fails").
    VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT status, fence, reason FROM runs WHERE id = $1 FOR UPDATE",
                                                 Params().Int(run_id)));
    if (r.rows() == 1 && r.Int(0, 1) == lease.fence && r.Text(0, 0) == RunStatusName(final_status) &&
        r.Text(0, 2) == reason) {
      return Status::Ok();
    }
  }
  VB_RETURN_IF_ERROR(CheckLease(&txn, lease, Cat("finish ", RunStatusName(final_status))));
  VB_RETURN_IF_ERROR(conn_
                         ->Exec("UPDATE runs SET status = $2, reason = $3, finished = " VB_PG_NOW ", "
                                "progress = CASE WHEN $2 = 'done' THEN 1.0 ELSE progress END, lease_expires = 0 "
                                "WHERE id = $1",
                                Params().Int(run_id).Text(RunStatusName(final_status)).Text(reason))
                         .status());
  if (execution) {
    // What executing it measured (schema v6) and which build did (v7, NULL when not known); the loop_* columns
    // stay NULL for a loop that was not paced.
    const ExecutionRecord& e = *execution;
    VB_RETURN_IF_ERROR(conn_
                           ->Exec("UPDATE runs SET exec_wall_s = $2, exec_simulated_s = $3, exec_samples = $4, "
                                  "exec_control_ticks = $5, exec_metrics_from_trajectory = $6, "
                                  "exec_build = $7 WHERE id = $1",
                                  Params()
                                      .Int(run_id)
                                      .Double(e.wall_s)
                                      .Double(e.simulated_s)
                                      .Int(e.samples)
                                      .Int(e.control_ticks)
                                      .Int(e.metrics_from_trajectory ? 1 : 0)
                                      .TextOrNull(e.build.empty() ? std::nullopt
                                                                  : std::optional<std::string_view>(e.build)))
                           .status());
    if (e.loop) {
      VB_RETURN_IF_ERROR(conn_
                             ->Exec("UPDATE runs SET loop_ticks = $2, loop_overruns = $3, loop_jitter_p50_s = $4, "
                                    "loop_jitter_p99_s = $5, loop_jitter_max_s = $6 WHERE id = $1",
                                    Params()
                                        .Int(run_id)
                                        .Int(e.loop->ticks)
                                        .Int(e.loop->overruns)
                                        .Double(e.loop->jitter_p50_s)
                                        .Double(e.loop->jitter_p99_s)
                                        .Double(e.loop->jitter_max_s))
                             .status());
    }
  }
  VB_RETURN_IF_ERROR(AddHistory(run_id, final_status, reason));
  for (const Metric& m : metrics) {
    // NaN is stored as NULL, as SQLite does, and GetMetrics() turns NULL back into NaN.
    VB_RETURN_IF_ERROR(conn_
                           ->Exec("INSERT INTO metrics (run_id, name, value) VALUES ($1, $2, $3)",
                                  Params().Int(run_id).Text(m.name).DoubleOrNull(m.value))
                           .status());
  }
  return txn.Commit();
}

StatusOr<RunStatus> PgStore::RequestCancel(std::int64_t run_id, const std::string& reason) {
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  VB_ASSIGN_OR_RETURN(Result r,
                         conn_->Exec("SELECT status FROM runs WHERE id = $1 FOR UPDATE", Params().Int(run_id)));
  if (r.rows() == 0) return RunNotFound(run_id);
  VB_ASSIGN_OR_RETURN(const RunStatus status, rules::StoredStatus(r.Text(0, 0), Cat("run ", run_id)));
  if (status == RunStatus::kQueued) {
    VB_RETURN_IF_ERROR(conn_
                           ->Exec("UPDATE runs SET status = 'cancelled', reason = $2, finished = " VB_PG_NOW
                                  " WHERE id = $1",
                                  Params().Int(run_id).Text(reason))
                           .status());
    VB_RETURN_IF_ERROR(AddHistory(run_id, RunStatus::kCancelled, reason));
    VB_RETURN_IF_ERROR(txn.Commit());
    return RunStatus::kCancelled;
  }
  if (status == RunStatus::kRunning) {
    VB_RETURN_IF_ERROR(conn_
                           ->Exec("UPDATE runs SET cancel_requested = true, reason = $2 WHERE id = $1",
                                  Params().Int(run_id).Text(reason))
                           .status());
    VB_RETURN_IF_ERROR(txn.Commit());
    return RunStatus::kRunning;
  }
  return Status::FailedPrecondition(
      Cat("run ", run_id, " is ", RunStatusName(status), ": only a queued or running run can be cancelled"));
}

StatusOr<bool> PgStore::CancelRequested(std::int64_t run_id) {
  VB_ASSIGN_OR_RETURN(Result r,
                         conn_->Exec("SELECT cancel_requested FROM runs WHERE id = $1", Params().Int(run_id)));
  if (r.rows() == 0) return RunNotFound(run_id);
  return r.Int(0, 0) != 0;
}

StatusOr<std::vector<std::int64_t>> PgStore::Interrupt(const std::string& select_sql, const Params& params,
                                                       bool lapsed, double stopped_unix_s) {
  // The stop's time, if known and not in the database's future (clocks differ): else now.
  const char* kStopped = "CASE WHEN $3::float8 > 0 AND $3::float8 < " VB_PG_NOW " THEN $3::float8 ELSE " VB_PG_NOW " END";
  struct Running {
    std::int64_t id;
    bool requeue;
    bool cancel_requested;
    std::string cancel_reason;
    std::string host;
  };
  VB_ASSIGN_OR_RETURN(Result rows, conn_->Exec(select_sql, params));
  std::vector<Running> running;
  for (int k = 0; k < rows.rows(); ++k) {
    running.push_back({rows.Int(k, 0), rows.Int(k, 1) != 0, rows.Int(k, 2) != 0, rows.Text(k, 3), rows.Text(k, 4)});
  }
  std::vector<std::int64_t> ids;
  for (const Running& r : running) {
    const std::string why = lapsed ? rules::LapsedReason(r.host) : std::string(rules::kRecoverReason);
    VB_RETURN_IF_ERROR(conn_
                           ->Exec(std::string("UPDATE runs SET status = 'interrupted', reason = $2, finished = ") +
                                      kStopped + ", lease_expires = 0 WHERE id = $1",
                                  Params().Int(r.id).Text(why).Double(stopped_unix_s))
                           .status());
    VB_RETURN_IF_ERROR(conn_
                           ->Exec(std::string("INSERT INTO status_history (run_id, status, at, reason) VALUES ($1, "
                                              "'interrupted', ") + kStopped + ", $2)",
                                  Params().Int(r.id).Text(why).Double(stopped_unix_s))
                           .status());
    std::int64_t times = 0;
    if (!r.cancel_requested && r.requeue) {
      VB_ASSIGN_OR_RETURN(times, conn_->QueryInt("SELECT count(*) FROM status_history WHERE run_id = $1 AND "
                                                    "status = 'interrupted'",
                                                    Params().Int(r.id)));
    }
    const rules::AfterInterrupt next = rules::AfterInterruption(r.cancel_requested, r.cancel_reason, r.requeue,
                                                                times, why);
    if (next.status == RunStatus::kCancelled || next.status == RunStatus::kFailed) {
      VB_RETURN_IF_ERROR(conn_
                             ->Exec("UPDATE runs SET status = $2, reason = $3 WHERE id = $1",
                                    Params().Int(r.id).Text(RunStatusName(next.status)).Text(next.reason))
                             .status());
      VB_RETURN_IF_ERROR(AddHistory(r.id, next.status, next.reason));
    } else if (next.status == RunStatus::kQueued) {
      // As on SQLite: back in the queue with its id, priority and age, asking for the bench it asked for; the
      // partial trace is dropped. The fence stays: the next claim moves it on, so the old attempt stays stale.
      VB_RETURN_IF_ERROR(conn_
                             ->Exec("UPDATE runs SET status = 'queued', bench_name = requested_bench, started = 0, "
                                    "finished = 0, progress = 0, cancel_requested = false, host = '', "
                                    "lease_expires = 0 WHERE id = $1",
                                    Params().Int(r.id))
                             .status());
      VB_RETURN_IF_ERROR(conn_->Exec("DELETE FROM trace_chunks WHERE run_id = $1", Params().Int(r.id)).status());
      VB_RETURN_IF_ERROR(AddHistory(r.id, RunStatus::kQueued, next.reason));
    }
    ids.push_back(r.id);
  }
  return ids;
}

StatusOr<int> PgStore::RecoverAfterCrashAt(const std::string& host, double stopped_unix_s) {
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  StatusOr<std::vector<std::int64_t>> ids =
      host.empty() ? Interrupt(
                         "SELECT id, requeue_on_interrupt, cancel_requested, reason, host FROM runs "
                         "WHERE status = 'running' ORDER BY id FOR UPDATE",
                         Params(), false, stopped_unix_s)
                   : Interrupt(
                         "SELECT id, requeue_on_interrupt, cancel_requested, reason, host FROM runs "
                         "WHERE status = 'running' AND host = $1 ORDER BY id FOR UPDATE",
                         Params().Text(host), false, stopped_unix_s);
  if (!ids.ok()) return ids.status();
  VB_RETURN_IF_ERROR(txn.Commit());
  return static_cast<int>(ids->size());
}

// ---- The lab ----

Status PgStore::Heartbeat(const HostRecord& host, double lease_ttl_s, const std::vector<Lease>& executing) {
  VB_RETURN_IF_ERROR(checks::CheckHeartbeat(host, lease_ttl_s));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  VB_RETURN_IF_ERROR(conn_
                         ->Exec("INSERT INTO hosts (name, address, benches_json, started, heartbeat) VALUES "
                                "($1, $2, $3, CASE WHEN $4 > 0 THEN $4 ELSE " VB_PG_NOW " END, " VB_PG_NOW ") "
                                "ON CONFLICT (name) DO UPDATE SET address = excluded.address, "
                                "benches_json = excluded.benches_json, started = excluded.started, "
                                "heartbeat = excluded.heartbeat",
                                Params()
                                    .Text(host.name)
                                    .Text(host.address)
                                    .Text(host.benches_json.empty() ? "[]" : host.benches_json)
                                    .Double(host.started_unix_s))
                         .status());
  if (lease_ttl_s > 0) {
    // Only the runs the host says it executes (a few: one per bench), each with its attempt's fence.
    for (const Lease& lease : executing) {
      VB_RETURN_IF_ERROR(conn_
                             ->Exec("UPDATE runs SET lease_expires = " VB_PG_NOW " + $2 "
                                    "WHERE status = 'running' AND host = $1 AND id = $3 AND fence = $4",
                                    Params().Text(host.name).Double(lease_ttl_s).Int(lease.run_id).Int(lease.fence))
                             .status());
    }
  }
  return txn.Commit();
}

StatusOr<std::vector<HostRecord>> PgStore::ListHosts() {
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT name, address, benches_json, started, heartbeat FROM hosts "
                                               "ORDER BY name"));
  std::vector<HostRecord> out;
  for (int k = 0; k < r.rows(); ++k) {
    out.push_back({r.Text(k, 0), r.Text(k, 1), r.Text(k, 2), r.Double(k, 3), r.Double(k, 4)});
  }
  return out;
}

StatusOr<std::vector<std::int64_t>> PgStore::RequeueLapsed() {
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  // SKIP LOCKED: a run another host is reaping (or writing for) right now is left to it.
  VB_ASSIGN_OR_RETURN(std::vector<std::int64_t> ids,
                         Interrupt("SELECT id, requeue_on_interrupt, cancel_requested, reason, host FROM runs "
                                   "WHERE status = 'running' AND lease_expires > 0 AND lease_expires < " VB_PG_NOW
                                   " ORDER BY id FOR UPDATE SKIP LOCKED",
                                   Params(), true));
  VB_RETURN_IF_ERROR(txn.Commit());
  return ids;
}

StatusOr<std::vector<StaleWrite>> PgStore::StaleWrites(std::int32_t limit, std::int64_t* total) {
  VB_RETURN_IF_ERROR(checks::CheckListLimit(limit));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT run_id, fence, current_fence, host, what, at FROM stale_writes "
                                               "ORDER BY id LIMIT $1",
                                               Params().Int(limit)));
  std::vector<StaleWrite> out;
  for (int k = 0; k < r.rows(); ++k) {
    out.push_back({r.Int(k, 0), r.Int(k, 1), r.Int(k, 2), r.Text(k, 3), r.Text(k, 4), r.Double(k, 5)});
  }
  if (total != nullptr) {
    VB_ASSIGN_OR_RETURN(*total, conn_->QueryInt("SELECT count(*) FROM stale_writes"));
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<bool> PgStore::ClaimNight(const std::string& night, const std::string& host) {
  VB_RETURN_IF_ERROR(checks::CheckNightClaim(night, host));
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("INSERT INTO nights_claimed (night, host, at) VALUES ($1, $2, " VB_PG_NOW
                                               ") ON CONFLICT (night) DO NOTHING",
                                               Params().Text(night).Text(host)));
  return r.affected() == 1;
}

// ---- Reading runs ----

StatusOr<RunRecord> PgStore::GetRun(std::int64_t run_id) { return LoadRun(run_id); }

// The SQL is run_query's (db/run_query.cc), shared with SQLite.
Params ParamsOf(const run_query::Query& q) {
  Params p;
  for (const run_query::Param& v : q.params) {
    if (const auto* i = std::get_if<std::int64_t>(&v)) p.Int(*i);
    else if (const auto* d = std::get_if<double>(&v)) p.Double(*d);
    else p.Text(std::get<std::string>(v));
  }
  return p;
}

StatusOr<std::vector<RunRecord>> PgStore::ListRuns(const RunFilter& f) {
  VB_RETURN_IF_ERROR(checks::ValidateFilter(f));
  const run_query::Query q = run_query::Page(f, run_query::Dialect::kPostgres);
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec(Cat("SELECT ", kRunColumns, q.sql), ParamsOf(q)));
  std::vector<RunRecord> out;
  out.reserve(static_cast<std::size_t>(r.rows()));
  for (int k = 0; k < r.rows(); ++k) {
    VB_ASSIGN_OR_RETURN(RunRecord run, ReadRun(r, k));
    out.push_back(std::move(run));
  }
  return out;
}

StatusOr<std::int64_t> PgStore::CountRuns(const RunFilter& f) {
  VB_RETURN_IF_ERROR(checks::ValidateFilter(f));
  const run_query::Query q = run_query::Count(f, run_query::Dialect::kPostgres);
  return conn_->QueryInt(Cat("SELECT count(*)", q.sql), ParamsOf(q));
}

StatusOr<std::vector<StatusChange>> PgStore::History(std::int64_t run_id) {
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_RETURN_IF_ERROR(StatusOf(run_id).status());
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT status, at, reason FROM status_history WHERE run_id = $1 "
                                               "ORDER BY id",
                                               Params().Int(run_id)));
  std::vector<StatusChange> out;
  for (int k = 0; k < r.rows(); ++k) {
    VB_ASSIGN_OR_RETURN(const RunStatus s, rules::StoredStatus(r.Text(k, 0), Cat("history of run ", run_id)));
    out.push_back({s, r.Double(k, 1), r.Text(k, 2)});
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<std::vector<Metric>> PgStore::GetMetrics(std::int64_t run_id) {
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_RETURN_IF_ERROR(StatusOf(run_id).status());
  // COLLATE "C": byte order, as SQLite's ORDER BY on text.
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT name, value FROM metrics WHERE run_id = $1 "
                                               "ORDER BY name COLLATE \"C\"",
                                               Params().Int(run_id)));
  std::vector<Metric> out;
  for (int k = 0; k < r.rows(); ++k) out.push_back({r.Text(k, 0), r.Double(k, 1)});
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<std::int64_t> PgStore::CountQueued(const std::string& submitter) {
  if (submitter.empty()) return conn_->QueryInt("SELECT count(*) FROM runs WHERE status = 'queued'");
  return conn_->QueryInt("SELECT count(*) FROM runs WHERE submitter = $1 AND status = 'queued'",
                         Params().Text(submitter));
}

StatusOr<std::int64_t> PgStore::StoredTraceBytes(const std::string& submitter) {
  return conn_->QueryInt(
      "SELECT COALESCE(SUM(octet_length(c.data)), 0)::int8 FROM runs r "
      "JOIN trace_chunks c ON c.run_id = r.id WHERE r.submitter = $1",
      Params().Text(submitter));
}

// ---- Traces ----

Status PgStore::AppendTraceChunk(const Lease& lease, const TraceChunk& chunk) {
  const std::int64_t run_id = lease.run_id;
  VB_RETURN_IF_ERROR(trace::ValidateChunk(chunk));
  const std::string where = Cat("trace chunk ", chunk.index, ": ");
  const std::string channels = trace::JoinChannels(chunk.channels);
  // Compressed before the transaction starts: the run's row is locked only for the insert.
  VB_RETURN_IF_ERROR(
      codec_.Encode(chunk.data.data(), chunk.channels.size(), static_cast<std::size_t>(chunk.samples), &encoded_)
          .WithContext(Cat("trace chunk ", chunk.index)));
  if (encoded_.size() > kMaxBlobBytes) {
    return Status::InvalidArgument(Cat(where, encoded_.size(),
                                       " bytes of data exceed the largest bytea PostgreSQL "
                                       "stores (",
                                       kMaxBlobBytes, " bytes): use smaller chunks"));
  }
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  // Trace chunks keep SQLite's rule (any status), but only the lease's attempt may write them.
  VB_RETURN_IF_ERROR(CheckLease(&txn, lease, Cat("trace chunk ", chunk.index)));
  VB_ASSIGN_OR_RETURN(Result last, conn_->Exec("SELECT idx, channels FROM trace_chunks WHERE run_id = $1 "
                                                  "ORDER BY idx DESC LIMIT 1",
                                                  Params().Int(run_id)));
  const bool any = last.rows() > 0;
  const std::int64_t next = any ? last.Int(0, 0) + 1 : 0;
  if (chunk.index < next) {
    return Status::AlreadyExists(Cat(where, "already stored for run ", run_id, " (the next index is ", next, ")"));
  }
  if (chunk.index > next) {
    return Status::InvalidArgument(
        Cat(where, "index must be ", next, " (chunks of run ", run_id, " are appended in order from 0, without gaps)"));
  }
  if (any && last.Text(0, 1) != channels) {
    return Status::InvalidArgument(Cat(where, "channels differ from those of the run's earlier chunks"));
  }
  VB_RETURN_IF_ERROR(conn_
                         ->Exec("INSERT INTO trace_chunks (run_id, idx, t0, period, samples, channels, data, codec) "
                                "VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
                                Params()
                                    .Int(run_id)
                                    .Int(chunk.index)
                                    .Double(chunk.t0_s)
                                    .Double(chunk.sample_period_s)
                                    .Int(chunk.samples)
                                    .Text(channels)
                                    .Bytes(encoded_.data(), encoded_.size())
                                    .Int(static_cast<std::int64_t>(trace::Codec::kShuffledZstd)))
                         .status());
  return txn.Commit();
}

StatusOr<std::vector<TraceChunk>> PgStore::ReadTrace(std::int64_t run_id) {
  std::vector<TraceChunk> out;
  VB_RETURN_IF_ERROR(ReadChunks(run_id, [&](TraceChunk& c, std::int64_t) {
    out.push_back(std::move(c));
    c = TraceChunk();
    return Status::Ok();
  }));
  return out;
}

Status PgStore::ForEachTraceChunk(std::int64_t run_id,
                                  const std::function<Status(const TraceChunk&, std::int64_t)>& fn) {
  return ReadChunks(run_id, [&](TraceChunk& c, std::int64_t total) { return fn(c, total); });
}

Status PgStore::ReadChunks(std::int64_t run_id, const std::function<Status(TraceChunk&, std::int64_t)>& fn) {
  // One snapshot for the listing and every chunk; the chunks' data is fetched one at a time, so only the
  // current chunk's bytes are in memory.
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_RETURN_IF_ERROR(StatusOf(run_id).status());
  VB_ASSIGN_OR_RETURN(Result meta, conn_->Exec("SELECT idx, t0, period, samples, channels, codec "
                                                  "FROM trace_chunks WHERE run_id = $1 ORDER BY idx",
                                                  Params().Int(run_id)));
  std::int64_t total = 0;
  for (int k = 0; k < meta.rows(); ++k) total += meta.Int(k, 3);
  TraceChunk c;
  for (int k = 0; k < meta.rows(); ++k) {
    c.index = static_cast<std::int32_t>(meta.Int(k, 0));
    c.t0_s = meta.Double(k, 1);
    c.sample_period_s = meta.Double(k, 2);
    c.samples = static_cast<std::int32_t>(meta.Int(k, 3));
    c.channels = trace::SplitChannels(meta.Text(k, 4));
    const std::string what = Cat("trace of run ", run_id, ", chunk ", c.index);
    if (c.index != k) return Status::DataLoss(Cat(what, ": expected chunk ", k, " (a chunk is missing)"));
    const std::size_t values = c.channels.size() * static_cast<std::size_t>(c.samples);
    const std::int64_t codec = meta.Int(k, 5);
    VB_ASSIGN_OR_RETURN(Result data, conn_->Exec("SELECT data FROM trace_chunks WHERE run_id = $1 AND idx = $2",
                                                    Params().Int(run_id).Int(c.index)));
    if (data.rows() != 1) return Status::DataLoss(Cat(what, ": vanished while being read"));
    const std::string_view bytes = data.Bytes(0, 0);
    if (codec == static_cast<std::int64_t>(trace::Codec::kRawFloat64)) {
      VB_RETURN_IF_ERROR(trace::CheckSize(bytes.size(), values, what));
      c.data.resize(values);
      if (!bytes.empty()) std::memcpy(c.data.data(), bytes.data(), bytes.size());
      trace::FromLittleEndian(&c.data);
    } else if (codec == static_cast<std::int64_t>(trace::Codec::kShuffledZstd)) {
      c.data.resize(values);
      VB_RETURN_IF_ERROR(codec_.Decode(bytes.data(), bytes.size(), c.channels.size(),
                                       static_cast<std::size_t>(c.samples), c.data.data(), what));
    } else {
      return Status::DataLoss(Cat(what, ": unknown codec ", codec));
    }
    VB_RETURN_IF_ERROR(fn(c, total));
  }
  return txn.Commit();
}

// ---- Baselines and regressions (db/regress_tables.cc on SQLite) ----

StatusOr<std::int32_t> PgStore::SaveBaseline(const std::string& name, const std::string& source,
                                             const std::string& note, const std::vector<BaselineEntry>& entries) {
  VB_RETURN_IF_ERROR(checks::ValidateBaseline(name, entries));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin());
  // Two hosts saving under one name at once: the second waits here, then numbers after the first.
  VB_RETURN_IF_ERROR(conn_->Exec("SELECT pg_advisory_xact_lock(hashtext($1))", Params().Text(name)).status());
  VB_ASSIGN_OR_RETURN(const std::int64_t last, conn_->QueryInt("SELECT COALESCE(MAX(version), 0)::int8 FROM "
                                                                  "baselines WHERE name = $1",
                                                                  Params().Text(name)));
  const std::int64_t version = last + 1;
  VB_ASSIGN_OR_RETURN(const std::int64_t id,
                         conn_->QueryInt("INSERT INTO baselines (name, version, created, source, note) VALUES "
                                         "($1, $2, " VB_PG_NOW ", $3, $4) RETURNING id",
                                         Params().Text(name).Int(version).Text(source).Text(note)));
  for (const BaselineEntry& e : entries) {
    VB_RETURN_IF_ERROR(
        conn_
            ->Exec("INSERT INTO baseline_metrics (baseline_id, case_name, metric, mean, spread, n) "
                   "VALUES ($1, $2, $3, $4, $5, $6)",
                   Params().Int(id).Text(e.case_name).Text(e.metric).Double(e.mean).Double(e.spread).Int(e.n))
            .status());
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return static_cast<std::int32_t>(version);
}

StatusOr<BaselineRecord> PgStore::GetBaseline(const std::string& name, std::int32_t version) {
  if (version < 0) return Status::InvalidArgument(Cat("version: must be >= 1 (0 = newest), got ", version));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  StatusOr<Result> head = version == 0 ? conn_->Exec(
                                             "SELECT id, version, created, source, note FROM baselines WHERE name = $1 "
                                             "ORDER BY version DESC LIMIT 1",
                                             Params().Text(name))
                                       : conn_->Exec(
                                             "SELECT id, version, created, source, note FROM baselines WHERE name = $1 "
                                             "AND version = $2",
                                             Params().Text(name).Int(version));
  if (!head.ok()) return head.status();
  if (head->rows() == 0) {
    return Status::NotFound(version == 0 ? Cat("baseline '", name, "' not found")
                                         : Cat("baseline '", name, "' has no version ", version));
  }
  BaselineRecord b;
  const std::int64_t id = head->Int(0, 0);
  b.name = name;
  b.version = static_cast<std::int32_t>(head->Int(0, 1));
  b.created_unix_s = head->Double(0, 2);
  b.source = head->Text(0, 3);
  b.note = head->Text(0, 4);
  VB_ASSIGN_OR_RETURN(Result m, conn_->Exec("SELECT case_name, metric, mean, spread, n FROM baseline_metrics "
                                               "WHERE baseline_id = $1 ORDER BY case_name COLLATE \"C\", "
                                               "metric COLLATE \"C\"",
                                               Params().Int(id)));
  for (int k = 0; k < m.rows(); ++k) {
    b.entries.push_back(
        {m.Text(k, 0), m.Text(k, 1), m.Double(k, 2), m.Double(k, 3), static_cast<std::int32_t>(m.Int(k, 4))});
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return b;
}

StatusOr<std::vector<BaselineRecord>> PgStore::ListBaselines() {
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT name, version, created, source, note FROM baselines "
                                               "ORDER BY name COLLATE \"C\", version"));
  std::vector<BaselineRecord> out;
  for (int k = 0; k < r.rows(); ++k) {
    BaselineRecord b;
    b.name = r.Text(k, 0);
    b.version = static_cast<std::int32_t>(r.Int(k, 1));
    b.created_unix_s = r.Double(k, 2);
    b.source = r.Text(k, 3);
    b.note = r.Text(k, 4);
    out.push_back(std::move(b));
  }
  return out;
}

constexpr const char* kRegressionColumns =
    "id, suite, baseline_name, baseline_version, batch_id, night, created, verdict";

RegressionRecord ReadRegression(const Result& r, int k) {
  RegressionRecord out;
  out.id = r.Int(k, 0);
  out.suite = r.Text(k, 1);
  out.baseline_name = r.Text(k, 2);
  out.baseline_version = static_cast<std::int32_t>(r.Int(k, 3));
  out.batch_id = r.Int(k, 4);
  out.night = r.Text(k, 5);
  out.created_unix_s = r.Double(k, 6);
  out.verdict = r.Text(k, 7);
  return out;
}

StatusOr<std::int64_t> PgStore::SaveRegression(const RegressionRecord& record) {
  VB_RETURN_IF_ERROR(checks::CheckRegression(record));
  return conn_->QueryInt(
      "INSERT INTO regressions (suite, baseline_name, baseline_version, batch_id, night, created, "
      "verdict, result_json) VALUES ($1, $2, $3, $4, $5, CASE WHEN $6 > 0 THEN $6 ELSE " VB_PG_NOW
      " END, $7, $8) RETURNING id",
      Params()
          .Text(record.suite)
          .Text(record.baseline_name)
          .Int(record.baseline_version)
          .Int(record.batch_id)
          .Text(record.night)
          .Double(record.created_unix_s)
          .Text(record.verdict)
          .Text(record.result_json));
}

StatusOr<RegressionRecord> PgStore::GetRegression(std::int64_t id) {
  static const std::string sql = Cat("SELECT ", kRegressionColumns, ", result_json FROM regressions WHERE id = $1");
  VB_ASSIGN_OR_RETURN(Result r, conn_->Exec(sql, Params().Int(id)));
  if (r.rows() == 0) return Status::NotFound(Cat("regression ", id, " not found"));
  RegressionRecord out = ReadRegression(r, 0);
  out.result_json = r.Text(0, 8);
  return out;
}

StatusOr<std::vector<RegressionRecord>> PgStore::ListRegressions(bool nights_only, std::int32_t limit) {
  VB_RETURN_IF_ERROR(checks::CheckListLimit(limit));
  VB_ASSIGN_OR_RETURN(Result r,
                         conn_->Exec(Cat("SELECT ", kRegressionColumns, " FROM regressions",
                                         nights_only ? " WHERE night != ''" : "", " ORDER BY id DESC LIMIT $1"),
                                     Params().Int(limit)));
  std::vector<RegressionRecord> out;
  for (int k = 0; k < r.rows(); ++k) out.push_back(ReadRegression(r, k));
  return out;
}

// ---- Retention ----
// The rules are PlanPrune's (db/prune_plan.h), shared with SQLite: this reads the facts and executes the plan.

StatusOr<PruneResult> PgStore::Prune(const PruneRequest& request) {
  VB_RETURN_IF_ERROR(checks::CheckPrune(request));
  pg::Transaction txn(conn_.get());
  VB_RETURN_IF_ERROR(txn.Begin(request.dry_run ? TxnKind::kRead : TxnKind::kWrite));
  PruneFacts facts;
  {
    VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT id, batch_id, night, suite, "
                                                 "CASE WHEN night <> '' THEN result_json ELSE '' END "
                                                 "FROM regressions WHERE batch_id != 0"));
    for (int k = 0; k < r.rows(); ++k)
      facts.regressions.push_back(
          {r.Int(k, 0), r.Int(k, 1), r.Text(k, 2), r.Text(k, 3), HealthBatchesOfNight(r.Text(k, 4))});
  }
  {
    VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT name, version, source FROM baselines ORDER BY id"));
    for (int k = 0; k < r.rows(); ++k)
      facts.baselines.push_back({r.Text(k, 0), static_cast<std::int32_t>(r.Int(k, 1)), r.Text(k, 2)});
  }
  {
    // No row locks: only finished runs are deleted, and nothing writes to a finished run any more.
    VB_ASSIGN_OR_RETURN(Result r, conn_->Exec("SELECT id, batch_id, name, status, finished FROM runs"));
    facts.runs.reserve(static_cast<std::size_t>(r.rows()));
    for (int k = 0; k < r.rows(); ++k) {
      PruneFacts::Run run{r.Int(k, 0), r.Int(k, 1), r.Text(k, 2), RunStatus::kDone, r.Double(k, 4)};
      VB_ASSIGN_OR_RETURN(run.status, rules::StoredStatus(r.Text(k, 3), Cat("run ", run.id)));
      facts.runs.push_back(std::move(run));
    }
  }
  PrunePlan plan = PlanPrune(facts, request);
  PruneResult& out = plan.result;
  for (std::int64_t id : plan.doomed) {
    VB_ASSIGN_OR_RETURN(const std::int64_t bytes,
                           conn_->QueryInt("SELECT COALESCE(SUM(octet_length(data)), 0)::int8 FROM trace_chunks "
                                           "WHERE run_id = $1",
                                           Params().Int(id)));
    out.trace_bytes += bytes;
  }
  if (!request.dry_run) {
    for (std::int64_t id : plan.doomed) {
      VB_RETURN_IF_ERROR(conn_->Exec("DELETE FROM runs WHERE id = $1", Params().Int(id)).status());
    }
    out.batches_deleted = 0;
    for (std::int64_t b : plan.empty_batches) {
      VB_ASSIGN_OR_RETURN(Result del, conn_->Exec("DELETE FROM batches WHERE id = $1 AND NOT EXISTS "
                                                     "(SELECT 1 FROM runs WHERE batch_id = $1)",
                                                     Params().Int(b)));
      out.batches_deleted += del.affected();
    }
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return std::move(out);
}

}  // namespace

StatusOr<std::unique_ptr<Store>> OpenPgStore(const std::string& location) {
  if (!pg::IsPostgresLocation(location)) {
    return Status::InvalidArgument(
        Cat("location: not a PostgreSQL connection string (postgresql://... or "
            "\"host=... dbname=...\"): \"",
            location, "\""));
  }
  VB_ASSIGN_OR_RETURN(std::unique_ptr<pg::Connection> conn, pg::Connection::Open(location));
  VB_ASSIGN_OR_RETURN(const int version, pg_schema::Migrate(conn.get(), pg_schema::Migrations()));
  return std::unique_ptr<Store>(std::make_unique<PgStore>(std::move(conn), version));
}

}  // namespace vb::db
