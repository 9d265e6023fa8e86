// The results store's interface (docs/store.md): runs with their exact spec, status history, metrics as rows,
// traces as chunks, batches, tags, baselines and regression results, the lab's hosts and leases, and the run queue
// itself (a server that dies loses no queued run). The values it reads and writes are db/records.h's. Its
// engines, SQLite for one machine (db/sqlite_store.h) and PostgreSQL for a lab of hosts (db/pg_store.h), depend
// on it, never the reverse; db/open_store.h opens either by location.
//
// Thread-safety: a Store is used by one thread at a time per connection; the server opens one Store per
// thread that needs it (both engines let connections read while another writes). Every method is a
// transaction: it either fully happens or not at all (nothing already stored is lost on error).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/status.h"
#include "db/records.h"

namespace vb::db {

class Store {
 public:
  virtual ~Store() = default;

  virtual int schema_version() const = 0;

  // A batch and its runs, atomically (all queued, or none). Returns the batch id; run ids in order in *run_ids.
  virtual StatusOr<std::int64_t> SubmitBatch(const std::string& submitter, const std::string& name,
                                             const std::string& batch_spec_json, std::vector<RunRecord> runs,
                                             std::vector<std::int64_t>* run_ids) = 0;

  // Queue: atomically picks the queued run with the highest priority (plus its aging, ClaimRequest::aging_s),
  // then the oldest (lowest id), whose bench_kind equals the request's (or is empty) and whose bench_name is
  // empty or equals the request's; marks it running on that bench and host with the next fence (and a lease
  // when lease_ttl_s > 0). nullopt when none is waiting. Concurrent claimers, in one process or on many hosts,
  // never get the same run.
  virtual StatusOr<std::optional<RunRecord>> ClaimNext(const ClaimRequest& request) = 0;
  // Writes for a claimed run: each refused as a stale write when `lease` no longer holds the run (see Lease).
  virtual Status SetProgress(const Lease& lease, double progress) = 0;
  // Final state with metrics and, for a run that executed, what executing it measured (all written in the same
  // transaction). FailedPrecondition if the run is not running.
  virtual Status Finish(const Lease& lease, RunStatus final_status, const std::string& reason,
                        const std::vector<Metric>& metrics, const std::optional<ExecutionRecord>& execution) = 0;
  // A run that did not execute (or whose execution is not known): no execution record.
  Status Finish(const Lease& lease, RunStatus final_status, const std::string& reason,
                const std::vector<Metric>& metrics) {
    return Finish(lease, final_status, reason, metrics, std::nullopt);
  }
  // Cancels a queued run at once (returns kCancelled); for a running run records the request and returns
  // kRunning (the worker stops it and calls Finish(kCancelled)); FailedPrecondition for finished runs.
  virtual StatusOr<RunStatus> RequestCancel(std::int64_t run_id, const std::string& reason) = 0;
  virtual StatusOr<bool> CancelRequested(std::int64_t run_id) = 0;
  // On server start: every run still marked running on `host` ("" = every running run: one machine) becomes
  // interrupted; those with requeue_on_interrupt are queued again (keeping their id, priority and age), unless
  // this was their third interruption: a run that keeps taking the server down is failed with the reason (a
  // poison run). Returns how many were interrupted.
  virtual StatusOr<int> RecoverAfterCrash(const std::string& host) = 0;
  // The same, for a process whose stop time is known (its spool's last sign of life, runs/spool.h): the runs'
  // `interrupted` entries (and their finish time) carry stopped_unix_s, not the restart's time (issue 39); a
  // time of 0, or one later than the store's clock, is taken as now. The re-queue itself is dated now.
  virtual StatusOr<int> RecoverAfterCrashAt(const std::string& host, double stopped_unix_s) {
    (void)stopped_unix_s;
    return RecoverAfterCrash(host);
  }

  // ---- The lab (docs/lab.md) ----
  // Registers or refreshes `host` (its heartbeat is the store's clock now) and renews to now + lease_ttl_s the
  // leases in `executing`: the runs the host is really executing right now, each still running on this host
  // with that fence. A run of the host that is not listed (its experiment ended and its result is not written
  // yet, or a claim whose answer was lost) is not renewed: its lease lapses and RequeueLapsed re-queues it,
  // so no run stays running with nobody executing it (issue 30).
  virtual Status Heartbeat(const HostRecord& host, double lease_ttl_s, const std::vector<Lease>& executing) = 0;
  virtual StatusOr<std::vector<HostRecord>> ListHosts() = 0;
  // Runs whose lease lapsed (their host stopped heartbeating): treated as RecoverAfterCrash treats a run of a
  // crashed host (interrupted, then re-queued or failed as poison). Any host may call it. Returns their ids.
  virtual StatusOr<std::vector<std::int64_t>> RequeueLapsed() = 0;
  // The writes refused as stale, oldest first (at most `limit`, 1..1000), and how many there were in all.
  virtual StatusOr<std::vector<StaleWrite>> StaleWrites(std::int32_t limit, std::int64_t* total) = 0;
  // True for exactly one caller per `night` (YYYY-MM-DD) across every host sharing the store: that host runs
  // the night; the others skip it.
  virtual StatusOr<bool> ClaimNight(const std::string& night, const std::string& host) = 0;

  virtual StatusOr<RunRecord> GetRun(std::int64_t run_id) = 0;
  // At most filter.limit runs matching the filter, in filter.order, after filter.after.
  virtual StatusOr<std::vector<RunRecord>> ListRuns(const RunFilter& filter) = 0;
  // How many runs match the filter on every page (filter.after and filter.limit ignored).
  virtual StatusOr<std::int64_t> CountRuns(const RunFilter& filter) = 0;
  virtual StatusOr<std::vector<StatusChange>> History(std::int64_t run_id) = 0;
  virtual StatusOr<std::vector<Metric>> GetMetrics(std::int64_t run_id) = 0;
  virtual StatusOr<std::int64_t> CountQueued(const std::string& submitter) = 0;
  // Bytes the stored trace chunks of `submitter`'s runs take (as stored: compressed since schema v4).
  virtual StatusOr<std::int64_t> StoredTraceBytes(const std::string& submitter) = 0;

  // Traces: chunks appended in index order while the run executes; read back in order.
  virtual Status AppendTraceChunk(const Lease& lease, const TraceChunk& chunk) = 0;
  virtual StatusOr<std::vector<TraceChunk>> ReadTrace(std::int64_t run_id) = 0;
  // Streams the chunks in order within one read transaction, reusing one buffer: nothing but the current
  // chunk is in memory. total_samples is the trace's length (the sum over its chunks). Stops at the first
  // error fn returns, and returns it.
  virtual Status ForEachTraceChunk(
      std::int64_t run_id, const std::function<Status(const TraceChunk& chunk, std::int64_t total_samples)>& fn) = 0;
  // Baselines (schema v2): never overwritten; saving under an existing name adds the next version, returned.
  virtual StatusOr<std::int32_t> SaveBaseline(const std::string& name, const std::string& source,
                                              const std::string& note, const std::vector<BaselineEntry>& entries) = 0;
  // version 0 = the newest. NotFound naming the name (and version).
  virtual StatusOr<BaselineRecord> GetBaseline(const std::string& name, std::int32_t version) = 0;
  // Every version of every baseline, without entries, by name then version.
  virtual StatusOr<std::vector<BaselineRecord>> ListBaselines() = 0;
  // Regression results: returns the new id. List: newest first, at most `limit` (1..1000), nights only if asked.
  virtual StatusOr<std::int64_t> SaveRegression(const RegressionRecord& record) = 0;
  virtual StatusOr<RegressionRecord> GetRegression(std::int64_t id) = 0;
  virtual StatusOr<std::vector<RegressionRecord>> ListRegressions(bool nights_only, std::int32_t limit) = 0;

  // Retention: deletes finished runs (done, failed, cancelled) that finished before the cutoff, with their
  // metrics, history, tags and traces, in one transaction; never a queued, running or interrupted run, never a
  // run of a batch that a baseline ("local batch N" in its source) or a regression result references, never
  // one of the newest keep_last finished runs. Batches left empty are deleted too. InvalidArgument naming the
  // field for a bad request.
  virtual StatusOr<PruneResult> Prune(const PruneRequest& request) = 0;
};

}  // namespace vb::db
