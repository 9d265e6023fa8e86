// The SQLite engine of db/store.h (db/sqlite_store.h). Schema and migrations: db/schema.cc; trace BLOB layout:
// db/trace_codec.h; the why of both: docs/store.md.
#include "db/sqlite_store.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <limits>
#include <map>
#include <set>
#include <string_view>
#include <unordered_set>
#include <utility>
#include <variant>

#include "common/format.h"
#include "db/checks.h"
#include "db/checkpointer.h"
#include "db/prune_plan.h"
#include "db/regress_tables.h"
#include "db/run_query.h"
#include "db/run_rules.h"
#include "db/schema.h"
#include "db/sqlite_conn.h"
#include "db/text.h"
#include "db/trace_codec.h"

namespace vb::db {

namespace {

using sql::Stmt;
using sql::Transaction;
using TxnKind = sql::Transaction::Kind;

constexpr int kBusyTimeoutMs = 5000;       // a writer waits this long for another connection's write lock
constexpr int kPageSizeBytes = 32768;      // for new databases (SQLite's default is 4096)
// Background checkpoints (db/checkpointer.h): requested each time the WAL grew by 32 MiB; a committing thread
// waits for one once the WAL passes 256 MiB. The WAL file is allowed to keep that size between resets (it is
// deleted when the last connection closes): truncating and re-growing it costs more than it saves.
constexpr int kCheckpointEveryPages = 1000;
constexpr int kWalWaitAbovePages = 8000;
constexpr std::int64_t kWalLimitBytes =
    static_cast<std::int64_t>(kWalWaitAbovePages + kCheckpointEveryPages) * kPageSizeBytes;
using rules::kRunColumns;
using rules::RunNotFound;

double NowUnixS() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

class SqliteStore final : public Store {
 public:
  SqliteStore(sql::Connection conn, int version) : conn_(std::move(conn)), version_(version) {
    // A file database gets its checkpoints on a thread of its own (db/checkpointer.h); if that cannot start,
    // or for :memory:, SQLite's automatic checkpoints stay on.
    Checkpointer::Options options;
    options.request_every_pages = kCheckpointEveryPages;
    options.wait_above_pages = kWalWaitAbovePages;
    checkpointer_ = Checkpointer::Start(sqlite3_db_filename(conn_.raw(), "main"), options);
    if (checkpointer_ != nullptr) checkpointer_->Attach(conn_.raw());
  }
  ~SqliteStore() override {
    if (checkpointer_ != nullptr) Checkpointer::Detach(conn_.raw());
  }
  SqliteStore(const SqliteStore&) = delete;
  SqliteStore& operator=(const SqliteStore&) = delete;

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
  // Helpers run inside the caller's transaction.
  StatusOr<RunStatus> StatusOf(std::int64_t run_id);  // NotFound for an unknown run
  Status AddHistory(std::int64_t run_id, RunStatus status, double at, const std::string& reason);
  StatusOr<RunRecord> ReadRun(const Stmt& row);  // a row of kRunColumns, with its tags
  StatusOr<RunRecord> LoadRun(std::int64_t run_id);
  StatusOr<std::int64_t> InterruptionsOfRun(std::int64_t run_id);  // 'interrupted' entries in its history
  // The fencing check of every write for a claimed run (docs/lab.md, "Leases and fencing"), inside the caller's
  // write transaction: Ok when `lease` still holds the run (it is running and its fence is the lease's).
  // Otherwise the refusal is recorded in stale_writes, *txn is committed (the record stays even though the
  // write does not happen) and FailedPrecondition "stale write: ..." is returned. NotFound for an unknown run.
  Status CheckLease(const Lease& lease, const std::string& what, Transaction* txn);
  // The runs in `ids` (running ones) stop being executed: interrupted, then cancelled (a cancel was asked),
  // failed (their kMaxInterruptions-th interruption: a poison run) or re-queued. RecoverAfterCrash and
  // RequeueLapsed; inside the caller's write transaction.
  // interrupted_at: the time the interrupted entries carry (0 = now).
  Status InterruptRunning(const std::vector<std::int64_t>& ids, const std::string& reason, double now,
                          double interrupted_at = 0.0);
  // The chunks of a run in order, in one read transaction; fn may take the chunk's contents (move from it).
  Status ReadChunks(std::int64_t run_id, const std::function<Status(TraceChunk&, std::int64_t)>& fn);

  sql::Connection conn_;
  int version_;
  trace::Codec1 codec_;             // zstd contexts and scratch, reused chunk after chunk
  std::string encoded_;             // the last chunk's compressed BLOB (reused buffer)
  std::vector<std::uint8_t> blob_;  // a compressed BLOB read back (reused buffer)
  std::unique_ptr<Checkpointer> checkpointer_;  // destroyed (thread joined) before conn_ closes
};

StatusOr<RunStatus> SqliteStore::StatusOf(std::int64_t run_id) {
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT status FROM runs WHERE id = ?1"));
  st.Bind(1, run_id);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return RunNotFound(run_id);
  return rules::StoredStatus(st.Text(0), Cat("run ", run_id));
}

Status SqliteStore::AddHistory(std::int64_t run_id, RunStatus status, double at, const std::string& reason) {
  VB_ASSIGN_OR_RETURN(
      Stmt st, conn_.Prepare("INSERT INTO status_history (run_id, status, at, reason) VALUES (?1, ?2, ?3, ?4)"));
  st.Bind(1, run_id);
  st.Bind(2, RunStatusName(status));
  st.Bind(3, at);
  st.Bind(4, reason);
  return st.Run();
}

StatusOr<RunRecord> SqliteStore::ReadRun(const Stmt& row) {
  VB_ASSIGN_OR_RETURN(RunRecord r, rules::RunFromRow(row));
  VB_ASSIGN_OR_RETURN(Stmt sweep,
                         conn_.Prepare("SELECT field, value FROM run_sweep WHERE run_id = ?1 ORDER BY axis"));
  sweep.Bind(1, r.id);
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool more, sweep.Step());
    if (!more) break;
    r.key.sweep.push_back({sweep.Text(0), sweep.Double(1)});
  }

  // Tags come back in submission order (rowid order).
  VB_ASSIGN_OR_RETURN(Stmt tags, conn_.Prepare("SELECT tag FROM run_tags WHERE run_id = ?1 ORDER BY rowid"));
  tags.Bind(1, r.id);
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool more, tags.Step());
    if (!more) break;
    r.tags.push_back(tags.Text(0));
  }
  return r;
}

StatusOr<RunRecord> SqliteStore::LoadRun(std::int64_t run_id) {
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare(Cat("SELECT ", kRunColumns, " FROM runs WHERE id = ?1")));
  st.Bind(1, run_id);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return RunNotFound(run_id);
  return ReadRun(st);
}

// ---- Submission and the queue ----

StatusOr<std::int64_t> SqliteStore::SubmitBatch(const std::string& submitter, const std::string& name,
                                                const std::string& batch_spec_json, std::vector<RunRecord> runs,
                                                std::vector<std::int64_t>* run_ids) {
  VB_RETURN_IF_ERROR(checks::ValidateBatch(submitter, runs));
  const double now = NowUnixS();
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));

  VB_ASSIGN_OR_RETURN(
      Stmt batch, conn_.Prepare("INSERT INTO batches (submitter, name, spec_json, created) VALUES (?1, ?2, ?3, ?4)"));
  batch.Bind(1, submitter);
  batch.Bind(2, name);
  batch.Bind(3, batch_spec_json);
  batch.Bind(4, now);
  VB_RETURN_IF_ERROR(batch.Run());
  const std::int64_t batch_id = sqlite3_last_insert_rowid(conn_.raw());

  std::vector<std::int64_t> ids;
  ids.reserve(runs.size());
  for (const RunRecord& r : runs) {
    VB_ASSIGN_OR_RETURN(
        Stmt run,
        conn_.Prepare("INSERT INTO runs (batch_id, name, controller, bench_kind, requested_bench, bench_name, "
                      "spec_json, submitter, priority, status, requeue_on_interrupt, submitted, key_name, "
                      "repeat_index, split, t_start_s) "
                      "VALUES (?1, ?2, ?3, ?4, ?5, ?5, ?6, ?7, ?8, 'queued', ?9, ?10, ?11, ?12, ?13, ?14)"));
    run.Bind(1, batch_id);
    run.Bind(2, r.key.DisplayName());
    run.Bind(3, r.controller);
    run.Bind(4, r.bench_kind);
    run.Bind(5, r.bench_name);
    run.Bind(6, r.spec_json);
    run.Bind(7, submitter);
    run.Bind(8, static_cast<std::int64_t>(r.priority));
    run.Bind(9, r.requeue_on_interrupt);
    run.Bind(10, now);
    run.Bind(11, r.key.name);
    run.Bind(12, r.key.repeat);
    run.Bind(13, r.split);
    run.Bind(14, r.t_start_s);  // NaN binds as NULL
    VB_RETURN_IF_ERROR(run.Run());
    const std::int64_t id = sqlite3_last_insert_rowid(conn_.raw());
    ids.push_back(id);
    for (std::size_t a = 0; a < r.key.sweep.size(); ++a) {
      VB_ASSIGN_OR_RETURN(Stmt sw, conn_.Prepare("INSERT INTO run_sweep (run_id, axis, field, value) "
                                                    "VALUES (?1, ?2, ?3, ?4)"));
      sw.Bind(1, id);
      sw.Bind(2, static_cast<std::int64_t>(a));
      sw.Bind(3, r.key.sweep[a].field);
      sw.Bind(4, r.key.sweep[a].value);
      VB_RETURN_IF_ERROR(sw.Run());
    }
    for (const std::string& tag : r.tags) {
      VB_ASSIGN_OR_RETURN(Stmt t, conn_.Prepare("INSERT INTO run_tags (run_id, tag) VALUES (?1, ?2)"));
      t.Bind(1, id);
      t.Bind(2, tag);
      VB_RETURN_IF_ERROR(t.Run());
    }
    VB_RETURN_IF_ERROR(AddHistory(id, RunStatus::kQueued, now, ""));
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  if (run_ids != nullptr) *run_ids = std::move(ids);
  return batch_id;
}

StatusOr<std::optional<RunRecord>> SqliteStore::ClaimNext(const ClaimRequest& request) {
  const std::string& bench_kind = request.bench_kind;
  const std::string& bench_name = request.bench_name;
  VB_RETURN_IF_ERROR(checks::CheckClaim(request));
  Transaction txn(&conn_);
  // BEGIN IMMEDIATE takes the database's single write lock before the SELECT: two claimers (threads or
  // processes) are serialised here, so the run one of them sees as queued is still queued when it updates it.
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  const double now = NowUnixS();
  // Without aging: walks runs_queue (status, priority DESC, id) in order and stops at the first compatible run.
  // With aging: a queued run's priority rises by one for every aging_s it has waited since it was submitted
  // (docs/lab.md, "Priorities and aging"), so every queued run is looked at (the order is not an index's).
  const bool aging = request.aging_s > 0;
  VB_ASSIGN_OR_RETURN(
      Stmt pick, conn_.Prepare(aging ? "SELECT id FROM runs WHERE status = 'queued' "
                                       "AND (bench_kind = '' OR bench_kind = ?1) "
                                       "AND (bench_name = '' OR bench_name = ?2) "
                                       "ORDER BY priority + CAST(max(?3 - submitted, 0) / ?4 AS INTEGER) DESC, id "
                                       "LIMIT 1"
                                     : "SELECT id FROM runs WHERE status = 'queued' "
                                       "AND (bench_kind = '' OR bench_kind = ?1) "
                                       "AND (bench_name = '' OR bench_name = ?2) "
                                       "ORDER BY priority DESC, id LIMIT 1"));
  pick.Bind(1, bench_kind);
  pick.Bind(2, bench_name);
  if (aging) {
    pick.Bind(3, now);
    pick.Bind(4, request.aging_s);
  }
  VB_ASSIGN_OR_RETURN(const bool found, pick.Step());
  if (!found) return std::optional<RunRecord>();  // the destructor ends the (empty) transaction
  const std::int64_t id = pick.Int(0);

  // The next attempt: a new fencing token; the lease (if any) lapses lease_ttl_s from now unless the host's
  // heartbeats renew it.
  VB_ASSIGN_OR_RETURN(Stmt claim, conn_.Prepare("UPDATE runs SET status = 'running', bench_name = ?2, "
                                                   "started = ?3, finished = 0, progress = 0, reason = '', "
                                                   "cancel_requested = 0, fence = fence + 1, host = ?4, "
                                                   "lease_expires = ?5 WHERE id = ?1"));
  claim.Bind(1, id);
  claim.Bind(2, bench_name);
  claim.Bind(3, now);
  claim.Bind(4, request.host);
  claim.Bind(5, request.lease_ttl_s > 0 ? now + request.lease_ttl_s : 0.0);
  VB_RETURN_IF_ERROR(claim.Run());
  VB_RETURN_IF_ERROR(AddHistory(id, RunStatus::kRunning, now,
                                request.host.empty() ? Cat("claimed by bench ", bench_name)
                                                     : Cat("claimed by bench ", bench_name, " on host ", request.host)));
  VB_ASSIGN_OR_RETURN(RunRecord run, LoadRun(id));
  VB_RETURN_IF_ERROR(txn.Commit());
  return std::optional<RunRecord>(std::move(run));
}

Status SqliteStore::SetProgress(const Lease& lease, double progress) {
  const std::int64_t run_id = lease.run_id;
  VB_RETURN_IF_ERROR(checks::CheckProgress(progress));
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  VB_RETURN_IF_ERROR(CheckLease(lease, "progress", &txn));
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("UPDATE runs SET progress = ?2 WHERE id = ?1"));
  st.Bind(1, run_id);
  st.Bind(2, progress);
  VB_RETURN_IF_ERROR(st.Run());
  return txn.Commit();
}

Status SqliteStore::Finish(const Lease& lease, RunStatus final_status, const std::string& reason,
                           const std::vector<Metric>& metrics, const std::optional<ExecutionRecord>& execution) {
  const std::int64_t run_id = lease.run_id;
  VB_RETURN_IF_ERROR(checks::CheckFinish(final_status, metrics));
  if (execution) VB_RETURN_IF_ERROR(checks::CheckExecution(*execution));

  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  {
    // A retry of a Finish that committed but whose caller did not learn it: the run is already in exactly the
    // state this attempt writes. Nothing to do, and not a stale write (as on PostgreSQL; docs/lab.md).
    VB_ASSIGN_OR_RETURN(Stmt done, conn_.Prepare("SELECT status, fence, reason FROM runs WHERE id = ?1"));
    done.Bind(1, run_id);
    VB_ASSIGN_OR_RETURN(const bool row, done.Step());
    if (row && done.Text(0) == RunStatusName(final_status) && done.Int(1) == lease.fence && done.Text(2) == reason)
      return Status::Ok();
  }
  VB_RETURN_IF_ERROR(CheckLease(lease, Cat("finish ", RunStatusName(final_status)), &txn));
  const double now = NowUnixS();
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("UPDATE runs SET status = ?2, reason = ?3, finished = ?4, "
                                                "progress = CASE WHEN ?2 = 'done' THEN 1.0 ELSE progress END, "
                                                "lease_expires = 0 WHERE id = ?1"));
  st.Bind(1, run_id);
  st.Bind(2, RunStatusName(final_status));
  st.Bind(3, reason);
  st.Bind(4, now);
  VB_RETURN_IF_ERROR(st.Run());
  if (execution) {
    // What executing it measured (schema v6) and which build did (v7); the loop_* columns stay NULL for a loop
    // that was not paced.
    const ExecutionRecord& e = *execution;
    VB_ASSIGN_OR_RETURN(Stmt ex, conn_.Prepare("UPDATE runs SET exec_wall_s = ?2, exec_simulated_s = ?3, "
                                                "exec_samples = ?4, exec_control_ticks = ?5, "
                                                "exec_metrics_from_trajectory = ?6, exec_build = NULLIF(?7, '') "
                                                "WHERE id = ?1"));
    ex.Bind(1, run_id);
    ex.Bind(2, e.wall_s);
    ex.Bind(3, e.simulated_s);
    ex.Bind(4, e.samples);
    ex.Bind(5, e.control_ticks);
    ex.Bind(6, e.metrics_from_trajectory);
    ex.Bind(7, e.build);  // "" (not known) is stored as NULL (schema v7)
    VB_RETURN_IF_ERROR(ex.Run());
    if (e.loop) {
      VB_ASSIGN_OR_RETURN(Stmt lp, conn_.Prepare("UPDATE runs SET loop_ticks = ?2, loop_overruns = ?3, "
                                                  "loop_jitter_p50_s = ?4, loop_jitter_p99_s = ?5, "
                                                  "loop_jitter_max_s = ?6 WHERE id = ?1"));
      lp.Bind(1, run_id);
      lp.Bind(2, e.loop->ticks);
      lp.Bind(3, e.loop->overruns);
      lp.Bind(4, e.loop->jitter_p50_s);
      lp.Bind(5, e.loop->jitter_p99_s);
      lp.Bind(6, e.loop->jitter_max_s);
      VB_RETURN_IF_ERROR(lp.Run());
    }
  }
  VB_RETURN_IF_ERROR(AddHistory(run_id, final_status, now, reason));
  for (const Metric& m : metrics) {
    // NaN binds as NULL (SQLite's rule) and GetMetrics() turns NULL back into NaN.
    VB_ASSIGN_OR_RETURN(Stmt ins, conn_.Prepare("INSERT INTO metrics (run_id, name, value) VALUES (?1, ?2, ?3)"));
    ins.Bind(1, run_id);
    ins.Bind(2, m.name);
    ins.Bind(3, m.value);
    VB_RETURN_IF_ERROR(ins.Run());
  }
  return txn.Commit();
}

StatusOr<RunStatus> SqliteStore::RequestCancel(std::int64_t run_id, const std::string& reason) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  VB_ASSIGN_OR_RETURN(const RunStatus status, StatusOf(run_id));
  if (status == RunStatus::kQueued) {
    const double now = NowUnixS();
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("UPDATE runs SET status = 'cancelled', reason = ?2, "
                                                  "finished = ?3 WHERE id = ?1"));
    st.Bind(1, run_id);
    st.Bind(2, reason);
    st.Bind(3, now);
    VB_RETURN_IF_ERROR(st.Run());
    VB_RETURN_IF_ERROR(AddHistory(run_id, RunStatus::kCancelled, now, reason));
    VB_RETURN_IF_ERROR(txn.Commit());
    return RunStatus::kCancelled;
  }
  if (status == RunStatus::kRunning) {
    // The worker polls CancelRequested() and ends the run with Finish(kCancelled); the reason is kept in the
    // row meanwhile (the status does not change, so there is no history row yet).
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("UPDATE runs SET cancel_requested = 1, reason = ?2 WHERE id = ?1"));
    st.Bind(1, run_id);
    st.Bind(2, reason);
    VB_RETURN_IF_ERROR(st.Run());
    VB_RETURN_IF_ERROR(txn.Commit());
    return RunStatus::kRunning;
  }
  return Status::FailedPrecondition(
      Cat("run ", run_id, " is ", RunStatusName(status), ": only a queued or running run can be cancelled"));
}

StatusOr<bool> SqliteStore::CancelRequested(std::int64_t run_id) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT cancel_requested FROM runs WHERE id = ?1"));
  st.Bind(1, run_id);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return RunNotFound(run_id);
  const bool requested = st.Int(0) != 0;
  VB_RETURN_IF_ERROR(txn.Commit());
  return requested;
}

StatusOr<std::int64_t> SqliteStore::InterruptionsOfRun(std::int64_t run_id) {
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT COUNT(*) FROM status_history WHERE run_id = ?1 AND "
                                                "status = 'interrupted'"));
  st.Bind(1, run_id);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  return row ? st.Int(0) : 0;
}

Status SqliteStore::CheckLease(const Lease& lease, const std::string& what, Transaction* txn) {
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT status, fence, host FROM runs WHERE id = ?1"));
  st.Bind(1, lease.run_id);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return RunNotFound(lease.run_id);
  VB_ASSIGN_OR_RETURN(const RunStatus status, rules::StoredStatus(st.Text(0), Cat("run ", lease.run_id)));
  const std::int64_t fence = st.Int(1);
  const std::string host = st.Text(2);
  std::optional<std::string> stale = rules::StaleWriteWhy(lease, what, status, fence, host);
  if (!stale) return Status::Ok();
  VB_ASSIGN_OR_RETURN(Stmt log, conn_.Prepare("INSERT INTO stale_writes (run_id, fence, current_fence, host, "
                                                 "what, at) VALUES (?1, ?2, ?3, ?4, ?5, ?6)"));
  log.Bind(1, lease.run_id);
  log.Bind(2, lease.fence);
  log.Bind(3, fence);
  log.Bind(4, status == RunStatus::kRunning ? host : std::string());
  log.Bind(5, what);
  log.Bind(6, NowUnixS());
  VB_RETURN_IF_ERROR(log.Run());
  VB_RETURN_IF_ERROR(txn->Commit());
  return Status::FailedPrecondition(std::move(*stale));
}

Status SqliteStore::InterruptRunning(const std::vector<std::int64_t>& ids, const std::string& reason, double now,
                                     double interrupted_at) {
  const double stopped = interrupted_at > 0.0 && interrupted_at < now ? interrupted_at : now;
  for (const std::int64_t id : ids) {
    bool requeue = false, cancel_requested = false;
    std::string cancel_reason;
    {
      VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT requeue_on_interrupt, cancel_requested, reason "
                                                    "FROM runs WHERE id = ?1 AND status = 'running'"));
      st.Bind(1, id);
      VB_ASSIGN_OR_RETURN(const bool row, st.Step());
      if (!row) continue;
      requeue = st.Int(0) != 0;
      cancel_requested = st.Int(1) != 0;
      cancel_reason = st.Text(2);
    }
    VB_ASSIGN_OR_RETURN(Stmt stop, conn_.Prepare("UPDATE runs SET status = 'interrupted', reason = ?2, "
                                                    "finished = ?3, lease_expires = 0 WHERE id = ?1"));
    stop.Bind(1, id);
    stop.Bind(2, reason);
    stop.Bind(3, stopped);
    VB_RETURN_IF_ERROR(stop.Run());
    VB_RETURN_IF_ERROR(AddHistory(id, RunStatus::kInterrupted, stopped, reason));

    std::int64_t times = 0;
    if (!cancel_requested && requeue) {
      VB_ASSIGN_OR_RETURN(times, InterruptionsOfRun(id));
    }
    const rules::AfterInterrupt next = rules::AfterInterruption(cancel_requested, cancel_reason, requeue, times, reason);
    if (next.status == RunStatus::kCancelled || next.status == RunStatus::kFailed) {
      VB_ASSIGN_OR_RETURN(Stmt end, conn_.Prepare("UPDATE runs SET status = ?2, reason = ?3 WHERE id = ?1"));
      end.Bind(1, id);
      end.Bind(2, RunStatusName(next.status));
      end.Bind(3, next.reason);
      VB_RETURN_IF_ERROR(end.Run());
      VB_RETURN_IF_ERROR(AddHistory(id, next.status, now, next.reason));
    } else if (next.status == RunStatus::kQueued) {
      // Back in the queue with its id, priority and age; the bench it asked for (not the one that was running
      // it), no host and no lease; its fence stays, so the interrupted attempt's late writes are refused, and the
      // next claim takes fence + 1. The partial trace of the interrupted attempt is dropped: the rerun writes its
      // own from chunk 0.
      VB_ASSIGN_OR_RETURN(Stmt requeue_st, conn_.Prepare("UPDATE runs SET status = 'queued', bench_name = "
                                                            "requested_bench, started = 0, finished = 0, "
                                                            "progress = 0, cancel_requested = 0, host = '', "
                                                            "lease_expires = 0 WHERE id = ?1"));
      requeue_st.Bind(1, id);
      VB_RETURN_IF_ERROR(requeue_st.Run());
      VB_ASSIGN_OR_RETURN(Stmt drop, conn_.Prepare("DELETE FROM trace_chunks WHERE run_id = ?1"));
      drop.Bind(1, id);
      VB_RETURN_IF_ERROR(drop.Run());
      VB_RETURN_IF_ERROR(AddHistory(id, RunStatus::kQueued, now, next.reason));
    }
  }
  return Status::Ok();
}

StatusOr<int> SqliteStore::RecoverAfterCrashAt(const std::string& host, double stopped_unix_s) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  std::vector<std::int64_t> running;
  {
    // "" = one machine: every running run is this server's. A host in a lab touches only its own runs.
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare(host.empty() ? "SELECT id FROM runs WHERE status = 'running' "
                                                                  "ORDER BY id"
                                                                : "SELECT id FROM runs WHERE status = 'running' "
                                                                  "AND host = ?1 ORDER BY id"));
    if (!host.empty()) st.Bind(1, host);
    while (true) {
      VB_ASSIGN_OR_RETURN(const bool row, st.Step());
      if (!row) break;
      running.push_back(st.Int(0));
    }
  }
  VB_RETURN_IF_ERROR(InterruptRunning(running, rules::kRecoverReason, NowUnixS(), stopped_unix_s));
  VB_RETURN_IF_ERROR(txn.Commit());
  return static_cast<int>(running.size());
}

// ---- The lab ----

Status SqliteStore::Heartbeat(const HostRecord& host, double lease_ttl_s, const std::vector<Lease>& executing) {
  VB_RETURN_IF_ERROR(checks::CheckHeartbeat(host, lease_ttl_s));
  const double now = NowUnixS();
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  VB_ASSIGN_OR_RETURN(Stmt up, conn_.Prepare("INSERT INTO hosts (name, address, benches_json, started, heartbeat) "
                                                "VALUES (?1, ?2, ?3, ?4, ?5) ON CONFLICT (name) DO UPDATE SET "
                                                "address = excluded.address, benches_json = excluded.benches_json, "
                                                "started = excluded.started, heartbeat = excluded.heartbeat"));
  up.Bind(1, host.name);
  up.Bind(2, host.address);
  up.Bind(3, host.benches_json.empty() ? std::string("[]") : host.benches_json);
  up.Bind(4, host.started_unix_s > 0 ? host.started_unix_s : now);
  up.Bind(5, now);
  VB_RETURN_IF_ERROR(up.Run());
  if (lease_ttl_s > 0) {
    for (const Lease& lease : executing) {
      VB_ASSIGN_OR_RETURN(Stmt renew, conn_.Prepare("UPDATE runs SET lease_expires = ?2 WHERE status = 'running' "
                                                       "AND host = ?1 AND id = ?3 AND fence = ?4"));
      renew.Bind(1, host.name);
      renew.Bind(2, now + lease_ttl_s);
      renew.Bind(3, lease.run_id);
      renew.Bind(4, lease.fence);
      VB_RETURN_IF_ERROR(renew.Run());
    }
  }
  return txn.Commit();
}

StatusOr<std::vector<HostRecord>> SqliteStore::ListHosts() {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT name, address, benches_json, started, heartbeat FROM hosts "
                                                "ORDER BY name"));
  std::vector<HostRecord> out;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    out.push_back({st.Text(0), st.Text(1), st.Text(2), st.Double(3), st.Double(4)});
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<std::vector<std::int64_t>> SqliteStore::RequeueLapsed() {
  const double now = NowUnixS();
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  std::vector<std::int64_t> lapsed;
  std::map<std::int64_t, std::string> host_of;
  {
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT id, host FROM runs WHERE status = 'running' AND "
                                                  "lease_expires > 0 AND lease_expires < ?1 ORDER BY id"));
    st.Bind(1, now);
    while (true) {
      VB_ASSIGN_OR_RETURN(const bool row, st.Step());
      if (!row) break;
      lapsed.push_back(st.Int(0));
      host_of[st.Int(0)] = st.Text(1);
    }
  }
  for (const std::int64_t id : lapsed) {
    const std::string& h = host_of[id];
    VB_RETURN_IF_ERROR(InterruptRunning({id}, rules::LapsedReason(h), now));
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return lapsed;
}

StatusOr<std::vector<StaleWrite>> SqliteStore::StaleWrites(std::int32_t limit, std::int64_t* total) {
  VB_RETURN_IF_ERROR(checks::CheckListLimit(limit));
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  if (total != nullptr) {
    VB_ASSIGN_OR_RETURN(Stmt count, conn_.Prepare("SELECT count(*) FROM stale_writes"));
    VB_ASSIGN_OR_RETURN(const bool row, count.Step());
    *total = row ? count.Int(0) : 0;
  }
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT run_id, fence, current_fence, host, what, at FROM "
                                                "stale_writes ORDER BY id LIMIT ?1"));
  st.Bind(1, static_cast<std::int64_t>(limit));
  std::vector<StaleWrite> out;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    out.push_back({st.Int(0), st.Int(1), st.Int(2), st.Text(3), st.Text(4), st.Double(5)});
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<bool> SqliteStore::ClaimNight(const std::string& night, const std::string& host) {
  VB_RETURN_IF_ERROR(checks::CheckNightClaim(night, host));
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("INSERT INTO nights_claimed (night, host, at) VALUES (?1, ?2, ?3) "
                                                "ON CONFLICT (night) DO NOTHING"));
  st.Bind(1, night);
  st.Bind(2, host);
  st.Bind(3, NowUnixS());
  VB_RETURN_IF_ERROR(st.Run());
  const bool won = sqlite3_changes(conn_.raw()) == 1;
  VB_RETURN_IF_ERROR(txn.Commit());
  return won;
}

// ---- Reading runs ----

StatusOr<RunRecord> SqliteStore::GetRun(std::int64_t run_id) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(RunRecord run, LoadRun(run_id));
  VB_RETURN_IF_ERROR(txn.Commit());
  return run;
}

// The SQL is run_query's (db/run_query.cc), shared with PostgreSQL; one text per combination of filters and
// order in use, each prepared once and cached like the others.
void BindQuery(Stmt* st, const run_query::Query& q) {
  for (std::size_t k = 0; k < q.params.size(); ++k) {
    const int i = static_cast<int>(k) + 1;
    std::visit([&](const auto& v) { st->Bind(i, v); }, q.params[k]);
  }
}

StatusOr<std::vector<RunRecord>> SqliteStore::ListRuns(const RunFilter& f) {
  VB_RETURN_IF_ERROR(checks::ValidateFilter(f));
  const run_query::Query q = run_query::Page(f, run_query::Dialect::kSqlite);
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare(Cat("SELECT ", kRunColumns, q.sql)));
  BindQuery(&st, q);
  std::vector<RunRecord> out;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    VB_ASSIGN_OR_RETURN(RunRecord run, ReadRun(st));
    out.push_back(std::move(run));
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<std::int64_t> SqliteStore::CountRuns(const RunFilter& f) {
  VB_RETURN_IF_ERROR(checks::ValidateFilter(f));
  const run_query::Query q = run_query::Count(f, run_query::Dialect::kSqlite);
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare(Cat("SELECT count(*)", q.sql)));
  BindQuery(&st, q);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return Status::Internal("count(*) returned no row");
  const std::int64_t n = st.Int(0);
  VB_RETURN_IF_ERROR(txn.Commit());
  return n;
}

StatusOr<std::vector<StatusChange>> SqliteStore::History(std::int64_t run_id) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_RETURN_IF_ERROR(StatusOf(run_id).status());
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT status, at, reason FROM status_history "
                                                "WHERE run_id = ?1 ORDER BY id"));
  st.Bind(1, run_id);
  std::vector<StatusChange> out;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    VB_ASSIGN_OR_RETURN(const RunStatus s, rules::StoredStatus(st.Text(0), Cat("history of run ", run_id)));
    out.push_back({s, st.Double(1), st.Text(2)});
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<std::vector<Metric>> SqliteStore::GetMetrics(std::int64_t run_id) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_RETURN_IF_ERROR(StatusOf(run_id).status());
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT name, value FROM metrics WHERE run_id = ?1 ORDER BY name"));
  st.Bind(1, run_id);
  std::vector<Metric> out;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    out.push_back({st.Text(0), st.IsNull(1) ? std::nan("") : st.Double(1)});
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<std::int64_t> SqliteStore::CountQueued(const std::string& submitter) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  // Two texts so that each uses its index (runs_queue, runs_submitter).
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare(submitter.empty()
                                                    ? "SELECT count(*) FROM runs WHERE status = 'queued'"
                                                    : "SELECT count(*) FROM runs WHERE submitter = ?1 AND "
                                                      "status = 'queued'"));
  if (!submitter.empty()) st.Bind(1, submitter);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return Status::Internal("count(*) returned no row");
  const std::int64_t n = st.Int(0);
  VB_RETURN_IF_ERROR(txn.Commit());
  return n;
}

StatusOr<std::int64_t> SqliteStore::StoredTraceBytes(const std::string& submitter) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  // runs_submitter finds the user's runs, the trace_chunks primary key their chunks; length() reads the
  // record header, not the BLOB.
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT COALESCE(SUM(length(c.data)), 0) FROM runs r "
                                                "JOIN trace_chunks c ON c.run_id = r.id WHERE r.submitter = ?1"));
  st.Bind(1, submitter);
  VB_ASSIGN_OR_RETURN(const bool row, st.Step());
  if (!row) return Status::Internal("sum() returned no row");
  const std::int64_t n = st.Int(0);
  VB_RETURN_IF_ERROR(txn.Commit());
  return n;
}

// ---- Traces ----

Status SqliteStore::AppendTraceChunk(const Lease& lease, const TraceChunk& chunk) {
  const std::int64_t run_id = lease.run_id;
  VB_RETURN_IF_ERROR(trace::ValidateChunk(chunk));
  const std::string where = Cat("trace chunk ", chunk.index, ": ");
  const std::string channels = trace::JoinChannels(chunk.channels);
  // Compressed before the write transaction starts: other writers never wait for zstd.
  VB_RETURN_IF_ERROR(codec_.Encode(chunk.data.data(), chunk.channels.size(), static_cast<std::size_t>(chunk.samples),
                                   &encoded_)
                         .WithContext(Cat("trace chunk ", chunk.index)));
  const std::uint64_t bytes = encoded_.size();
  const auto max_bytes = static_cast<std::uint64_t>(sqlite3_limit(conn_.raw(), SQLITE_LIMIT_LENGTH, -1));
  if (bytes > max_bytes) {
    return Status::InvalidArgument(Cat(where, bytes, " bytes of data exceed the largest BLOB SQLite stores here (",
                                       max_bytes, " bytes): use smaller chunks"));
  }

  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  VB_RETURN_IF_ERROR(CheckLease(lease, Cat("trace chunk ", chunk.index), &txn));
  {
    // The last chunk so far (primary key order); its channels must match (all chunks of a trace share them).
    VB_ASSIGN_OR_RETURN(Stmt last, conn_.Prepare("SELECT idx, channels FROM trace_chunks WHERE run_id = ?1 "
                                                    "ORDER BY idx DESC LIMIT 1"));
    last.Bind(1, run_id);
    VB_ASSIGN_OR_RETURN(const bool any, last.Step());
    const std::int64_t next = any ? last.Int(0) + 1 : 0;
    if (chunk.index < next) {
      return Status::AlreadyExists(Cat(where, "already stored for run ", run_id, " (the next index is ", next, ")"));
    }
    if (chunk.index > next) {
      return Status::InvalidArgument(Cat(where, "index must be ", next, " (chunks of run ", run_id,
                                         " are appended in order from 0, without gaps)"));
    }
    if (any && last.Text(1) != channels) {
      return Status::InvalidArgument(Cat(where, "channels differ from those of the run's earlier chunks"));
    }
  }

  VB_ASSIGN_OR_RETURN(Stmt ins, conn_.Prepare("INSERT INTO trace_chunks (run_id, idx, t0, period, samples, "
                                                 "channels, data, codec) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)"));
  ins.Bind(1, run_id);
  ins.Bind(2, static_cast<std::int64_t>(chunk.index));
  ins.Bind(3, chunk.t0_s);
  ins.Bind(4, chunk.sample_period_s);
  ins.Bind(5, static_cast<std::int64_t>(chunk.samples));
  ins.Bind(6, channels);
  ins.BindBlobNoCopy(7, encoded_.data(), encoded_.size());
  ins.Bind(8, static_cast<std::int64_t>(trace::Codec::kShuffledZstd));
  VB_RETURN_IF_ERROR(ins.Run());
  return txn.Commit();
}

StatusOr<std::vector<TraceChunk>> SqliteStore::ReadTrace(std::int64_t run_id) {
  std::vector<TraceChunk> out;
  // Each chunk is decoded into its own vector and moved into the result: no copy of the whole trace.
  VB_RETURN_IF_ERROR(ReadChunks(run_id, [&](TraceChunk& c, std::int64_t) {
    out.push_back(std::move(c));
    c = TraceChunk();
    return Status::Ok();
  }));
  return out;
}

Status SqliteStore::ForEachTraceChunk(std::int64_t run_id,
                                      const std::function<Status(const TraceChunk&, std::int64_t)>& fn) {
  return ReadChunks(run_id, [&](TraceChunk& c, std::int64_t total) { return fn(c, total); });
}

Status SqliteStore::ReadChunks(std::int64_t run_id, const std::function<Status(TraceChunk&, std::int64_t)>& fn) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_RETURN_IF_ERROR(StatusOf(run_id).status());
  std::int64_t total = 0;
  {
    VB_ASSIGN_OR_RETURN(Stmt sum, conn_.Prepare("SELECT COALESCE(SUM(samples), 0) FROM trace_chunks WHERE run_id = ?1"));
    sum.Bind(1, run_id);
    VB_ASSIGN_OR_RETURN(const bool row, sum.Step());
    if (row) total = sum.Int(0);
  }
  // length(data) comes from the record header without reading the BLOB; the BLOB itself is then copied straight
  // into the chunk's buffer by incremental BLOB I/O (one copy instead of two).
  VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT rowid, idx, t0, period, samples, channels, length(data), "
                                                "codec FROM trace_chunks WHERE run_id = ?1 ORDER BY idx"));
  st.Bind(1, run_id);
  sql::BlobReader blob(conn_.raw(), "trace_chunks", "data");
  TraceChunk c;  // reused unless fn takes it: its buffer keeps its capacity from chunk to chunk
  std::int32_t expected = 0;
  while (true) {
    VB_ASSIGN_OR_RETURN(const bool row, st.Step());
    if (!row) break;
    c.index = static_cast<std::int32_t>(st.Int(1));
    c.t0_s = st.Double(2);
    c.sample_period_s = st.Double(3);
    c.samples = static_cast<std::int32_t>(st.Int(4));
    c.channels = trace::SplitChannels(st.Text(5));
    const std::string what = Cat("trace of run ", run_id, ", chunk ", c.index);
    if (c.index != expected) {
      return Status::DataLoss(Cat(what, ": expected chunk ", expected, " (a chunk is missing)"));
    }
    const std::size_t values = c.channels.size() * static_cast<std::size_t>(c.samples);
    const std::int64_t codec = st.Int(7);
    if (codec == static_cast<std::int64_t>(trace::Codec::kRawFloat64)) {  // written before schema v4
      VB_RETURN_IF_ERROR(trace::CheckSize(static_cast<std::size_t>(st.Int(6)), values, what));
      VB_ASSIGN_OR_RETURN(const std::size_t bytes, blob.Open(st.Int(0)));
      VB_RETURN_IF_ERROR(trace::CheckSize(bytes, values, what));
      c.data.resize(values);
      VB_RETURN_IF_ERROR(blob.Read(c.data.data(), bytes));
      trace::FromLittleEndian(&c.data);
    } else if (codec == static_cast<std::int64_t>(trace::Codec::kShuffledZstd)) {
      VB_ASSIGN_OR_RETURN(const std::size_t bytes, blob.Open(st.Int(0)));
      blob_.resize(bytes);
      VB_RETURN_IF_ERROR(blob.Read(blob_.data(), bytes));
      c.data.resize(values);
      VB_RETURN_IF_ERROR(codec_.Decode(blob_.data(), bytes, c.channels.size(), static_cast<std::size_t>(c.samples),
                                       c.data.data(), what));
    } else {
      return Status::DataLoss(Cat(what, ": unknown codec ", codec));
    }
    VB_RETURN_IF_ERROR(fn(c, total));
    ++expected;
  }
  return txn.Commit();
}

// ---- Retention ----
// The rules are PlanPrune's (db/prune_plan.h), shared with PostgreSQL: this reads the facts and executes the plan.

StatusOr<PruneResult> SqliteStore::Prune(const PruneRequest& request) {
  VB_RETURN_IF_ERROR(checks::CheckPrune(request));
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(request.dry_run ? TxnKind::kRead : TxnKind::kWrite));

  PruneFacts facts;
  {
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT id, batch_id, night, suite, "
                                                  "CASE WHEN night != '' THEN result_json ELSE '' END "
                                                  "FROM regressions WHERE batch_id != 0"));
    while (true) {
      VB_ASSIGN_OR_RETURN(const bool row, st.Step());
      if (!row) break;
      facts.regressions.push_back({st.Int(0), st.Int(1), st.Text(2), st.Text(3), HealthBatchesOfNight(st.Text(4))});
    }
  }
  {
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT name, version, source FROM baselines ORDER BY id"));
    while (true) {
      VB_ASSIGN_OR_RETURN(const bool row, st.Step());
      if (!row) break;
      facts.baselines.push_back({st.Text(0), static_cast<std::int32_t>(st.Int(1)), st.Text(2)});
    }
  }
  {
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT id, batch_id, name, status, finished FROM runs"));
    while (true) {
      VB_ASSIGN_OR_RETURN(const bool row, st.Step());
      if (!row) break;
      PruneFacts::Run r{st.Int(0), st.Int(1), st.Text(2), RunStatus::kDone, st.Double(4)};
      VB_ASSIGN_OR_RETURN(r.status, rules::StoredStatus(st.Text(3), Cat("run ", r.id)));
      facts.runs.push_back(std::move(r));
    }
  }
  PrunePlan plan = PlanPrune(facts, request);
  PruneResult& out = plan.result;
  {
    VB_ASSIGN_OR_RETURN(Stmt st, conn_.Prepare("SELECT COALESCE(SUM(length(data)), 0) FROM trace_chunks "
                                                  "WHERE run_id = ?1"));
    for (std::int64_t id : plan.doomed) {
      st.Reset();
      st.Bind(1, id);
      VB_ASSIGN_OR_RETURN(const bool row, st.Step());
      if (row) out.trace_bytes += st.Int(0);
    }
  }
  if (!request.dry_run) {
    // Children go with their run (ON DELETE CASCADE): tags, history, metrics, sweep point, trace chunks.
    VB_ASSIGN_OR_RETURN(Stmt del, conn_.Prepare("DELETE FROM runs WHERE id = ?1"));
    for (std::int64_t id : plan.doomed) {
      del.Reset();
      del.Bind(1, id);
      VB_RETURN_IF_ERROR(del.Run());
    }
    VB_ASSIGN_OR_RETURN(Stmt empty, conn_.Prepare("DELETE FROM batches WHERE id = ?1 AND NOT EXISTS "
                                                     "(SELECT 1 FROM runs WHERE batch_id = ?1)"));
    out.batches_deleted = 0;
    for (std::int64_t b : plan.empty_batches) {
      empty.Reset();
      empty.Bind(1, b);
      VB_RETURN_IF_ERROR(empty.Run());
      out.batches_deleted += sqlite3_changes(conn_.raw());
    }
  }
  VB_RETURN_IF_ERROR(txn.Commit());
  return std::move(out);
}

}  // namespace

StatusOr<std::unique_ptr<Store>> OpenSqliteStore(const std::string& path) {
  if (path.empty()) {
    return Status::InvalidArgument("path: must not be empty (\":memory:\" opens a private in-memory database)");
  }
  const std::string where = Cat("database '", path, "'");
  VB_ASSIGN_OR_RETURN(sql::Connection conn, sql::Connection::Open(path));
  sqlite3_busy_timeout(conn.raw(), kBusyTimeoutMs);
  if (sqlite3_db_readonly(conn.raw(), "main") == 1) {
    return Status::Unavailable(Cat(where, ": the file is read-only, and the store must write to it"));
  }

  // Check the version before anything can write (switching to WAL rewrites the header of a rollback-journal
  // file): a database from a newer build is left exactly as it was.
  StatusOr<int> version = schema::ReadVersion(&conn);
  if (!version.ok()) return version.status().WithContext(where);
  VB_RETURN_IF_ERROR(schema::CheckKnown(*version, schema::Migrations(), path));

  if (*version == 0) {
    // A new database, or somebody else's: ours always has a version once it has tables.
    StatusOr<std::int64_t> objects = conn.QueryInt("SELECT count(*) FROM sqlite_schema");
    if (!objects.ok()) return objects.status().WithContext(where);
    if (*objects != 0) {
      return Status::FailedPrecondition(Cat(where, " is not a valvebench database (it has tables but no schema "
                                            "version); the file was left untouched"));
    }
    // Large pages: a trace BLOB spans 8x fewer pages than at SQLite's default 4 KiB, and trace ingest is ~1.7x
    // faster (docs/store.md). Only takes effect on an empty file, before WAL mode is set.
    VB_RETURN_IF_ERROR(conn.Exec(Cat("PRAGMA page_size = ", kPageSizeBytes)).WithContext(where));
  }
  // WAL: readers never block the writer nor each other, and several Stores (threads, processes) share the file.
  // synchronous=NORMAL: no fsync per commit; a committed transaction survives a crash of the process, only an
  // OS crash or power loss can lose the last few (the file stays consistent either way; docs/store.md).
  StatusOr<std::string> mode = conn.QueryText("PRAGMA journal_mode = WAL");
  if (!mode.ok()) return mode.status().WithContext(where);
  if (*mode != "wal" && *mode != "memory") {
    return Status::Unavailable(Cat(where, ": cannot switch to WAL journal mode (it stays in '", *mode,
                                   "' mode); is the file on a network filesystem?"));
  }
  VB_RETURN_IF_ERROR(conn.Exec("PRAGMA synchronous = NORMAL").WithContext(where));
  // A WAL that grew beyond the checkpointer's bound (long readers pin old frames) is cut back to it at the
  // next reset instead of keeping its high-water mark on disk.
  StatusOr<std::int64_t> limit = conn.QueryInt(Cat("PRAGMA journal_size_limit = ", kWalLimitBytes));
  if (!limit.ok()) return limit.status().WithContext(where);
  VB_RETURN_IF_ERROR(conn.Exec("PRAGMA foreign_keys = ON").WithContext(where));
  StatusOr<std::int64_t> fk = conn.QueryInt("PRAGMA foreign_keys");
  if (!fk.ok()) return fk.status().WithContext(where);
  if (*fk != 1) return Status::Internal("this SQLite library was built without foreign key support");

  StatusOr<int> migrated = schema::Migrate(&conn, schema::Migrations(), path);
  if (!migrated.ok()) return migrated.status();  // Migrate() names the file
  return std::unique_ptr<Store>(std::make_unique<SqliteStore>(std::move(conn), *migrated));
}


// Baselines and regressions: the SQL is in db/regress_tables.cc; each method is one transaction here.
StatusOr<std::int32_t> SqliteStore::SaveBaseline(const std::string& name, const std::string& source,
                                                 const std::string& note, const std::vector<BaselineEntry>& entries) {
  VB_RETURN_IF_ERROR(checks::ValidateBaseline(name, entries));
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  VB_ASSIGN_OR_RETURN(const int version,
                         regress_tables::InsertBaseline(&conn_, name, source, note, entries, NowUnixS()));
  VB_RETURN_IF_ERROR(txn.Commit());
  return version;
}

StatusOr<BaselineRecord> SqliteStore::GetBaseline(const std::string& name, std::int32_t version) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(BaselineRecord b, regress_tables::LoadBaseline(&conn_, name, version));
  VB_RETURN_IF_ERROR(txn.Commit());
  return b;
}

StatusOr<std::vector<BaselineRecord>> SqliteStore::ListBaselines() {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(std::vector<BaselineRecord> out, regress_tables::ListBaselines(&conn_));
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

StatusOr<std::int64_t> SqliteStore::SaveRegression(const RegressionRecord& record) {
  VB_RETURN_IF_ERROR(checks::CheckRegression(record));
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kWrite));
  VB_ASSIGN_OR_RETURN(const std::int64_t id, regress_tables::InsertRegression(&conn_, record, NowUnixS()));
  VB_RETURN_IF_ERROR(txn.Commit());
  return id;
}

StatusOr<RegressionRecord> SqliteStore::GetRegression(std::int64_t id) {
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(RegressionRecord r, regress_tables::LoadRegression(&conn_, id));
  VB_RETURN_IF_ERROR(txn.Commit());
  return r;
}

StatusOr<std::vector<RegressionRecord>> SqliteStore::ListRegressions(bool nights_only, std::int32_t limit) {
  VB_RETURN_IF_ERROR(checks::CheckListLimit(limit));
  Transaction txn(&conn_);
  VB_RETURN_IF_ERROR(txn.Begin(TxnKind::kRead));
  VB_ASSIGN_OR_RETURN(std::vector<RegressionRecord> out,
                         regress_tables::ListRegressions(&conn_, nights_only, limit));
  VB_RETURN_IF_ERROR(txn.Commit());
  return out;
}

}  // namespace vb::db
