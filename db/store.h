// The SQLite results store: runs with their exact spec, status history, metrics as rows, traces as chunked
// BLOBs, batches, tags, and the run queue itself (a server that dies loses no queued run).
//
// Thread-safety: a Store is used by one thread at a time per connection; the server opens one Store per
// thread that needs it (SQLite WAL lets readers and one writer proceed concurrently). Every method is a
// transaction: it either fully happens or not at all (nothing already stored is lost on error).
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/run_key.h"
#include "common/run_status.h"
#include "common/status.h"

namespace vb::db {

// The statuses and their names are common/run_status.h's (the store keeps the names in its status columns).
using vb::ParseRunStatus;
using vb::RunStatus;
using vb::RunStatusName;

struct RunRecord {
  std::int64_t id = 0;
  std::int64_t batch_id = 0;
  RunKey key;                       // spec name, sweep point, repeat (columns since schema v3)
  std::string controller;           // law name, e.g. "pi_current"
  std::string bench_kind;           // spec's bench selector kind ("emulated", ...)
  std::string bench_name;           // spec's requested bench ("" = any); after claiming: the bench that ran it
  std::string spec_json;            // the exact single-run spec, verbatim
  std::string submitter;            // token's user name
  std::int32_t priority = 0;        // higher runs first
  RunStatus status = RunStatus::kQueued;
  std::string reason;               // why it failed / was cancelled / was interrupted
  bool requeue_on_interrupt = true; // re-queue after a server crash (spec allows it)
  double submitted_unix_s = 0.0, started_unix_s = 0.0, finished_unix_s = 0.0;
  double progress = 0.0;            // 0..1, last reported
  std::vector<std::string> tags;
  // Imported (measured) runs only, schema v3: the dataset's split ("fit", "holdout"; "" = none) and the run's
  // start time within its dataset session (NaN = not an imported run).
  std::string split;
  double t_start_s = std::numeric_limits<double>::quiet_NaN();
};

struct StatusChange {
  RunStatus status;
  double at_unix_s;
  std::string reason;
};

struct Metric {
  std::string name;
  double value;
};

// A trace chunk: consecutive samples of all channels, stored as one BLOB (channel-major float64 arrays,
// `channels` names them in order). Chunks of one run are numbered from 0.
struct TraceChunk {
  std::int32_t index = 0;
  double t0_s = 0.0;
  double sample_period_s = 0.0;
  std::int32_t samples = 0;
  std::vector<std::string> channels;
  std::vector<double> data;         // channels.size() * samples values, channel-major
};

struct RunFilter {
  std::optional<RunStatus> status;
  std::string tag;                  // runs carrying this tag
  std::int64_t batch_id = 0;        // 0 = any
  std::string controller;
  std::string bench_name;
  std::string submitter;
  double submitted_after_unix_s = 0.0;
  double submitted_before_unix_s = 0.0;  // 0 = no bound
  std::int64_t after_id = 0;        // paging: runs with id > after_id
  std::int32_t limit = 100;         // page size (1..1000)
};

// A named, versioned set of metric values with their spread over repeats (benchctl baseline; docs/regress.md).
struct BaselineEntry {
  std::string case_name;            // spec name + sweep tags (repeats share it)
  std::string metric;
  double mean = 0.0;
  double spread = 0.0;              // sample standard deviation over repeats
  std::int32_t n = 0;               // runs with a finite value
};
struct BaselineRecord {
  std::string name;
  std::int32_t version = 0;         // 1, 2, ...: a new set under an existing name is the next version
  double created_unix_s = 0.0;
  std::string source;               // where the values came from, e.g. "local batch 12"
  std::string note;
  std::vector<BaselineEntry> entries;  // empty in listings
};
// A regression run's outcome (the full comparison is kept as JSON for reports).
struct RegressionRecord {
  std::int64_t id = 0;
  std::string suite;
  std::string baseline_name;
  std::int32_t baseline_version = 0;
  std::int64_t batch_id = 0;        // 0 = runs not in this store
  std::string night;                // YYYY-MM-DD for a scheduled night, "" otherwise
  double created_unix_s = 0.0;
  std::string verdict;              // "passed" | "regressed" | "error"
  std::string result_json;          // empty in listings
};

// Retention (docs/store.md, "Retention"): which finished runs to delete, with their traces.
struct PruneRequest {
  double finished_before_unix_s = 0.0;  // candidates: runs that finished before this instant (> 0)
  std::int32_t keep_last = 0;           // the newest N finished runs (by id) are kept whatever their age (>= 0)
  bool dry_run = false;                 // decide and report, delete nothing
  // Batches that something outside this store references (the server's configured baseline file): kept.
  std::vector<std::int64_t> protected_batches;
  std::string protected_why;            // says what references them, e.g. "the server's baseline 'main' v2"
};
// One run prune looked at: deleted (or would be, in a dry run) or kept, and why.
struct PruneDecision {
  std::int64_t run_id = 0;
  std::int64_t batch_id = 0;
  std::string name;                     // RunKey::DisplayName()
  RunStatus status = RunStatus::kDone;
  double finished_unix_s = 0.0;
  std::string why;                      // e.g. "finished 2026-10-01 (older than the cutoff)", "baseline 'ci' v3 ..."
};
struct PruneResult {
  std::vector<PruneDecision> deleted;   // in a dry run: what would be deleted
  // Runs old enough to go but kept (a baseline or regression references them, among the newest N), and every
  // queued, running or interrupted run (never touched).
  std::vector<PruneDecision> kept;
  std::int64_t newer_kept = 0;          // finished runs newer than the cutoff (kept; not listed)
  std::int64_t trace_bytes = 0;         // stored trace bytes of the deleted runs
  std::int64_t batches_deleted = 0;     // batches left without runs, deleted with them
};

class Store {
 public:
  // Opens (creating if needed) the database at path, with WAL, foreign keys and busy timeout on, and migrates
  // the schema to the current version. ":memory:" works for tests.
  static StatusOr<std::unique_ptr<Store>> Open(const std::string& path);
  virtual ~Store() = default;

  virtual int schema_version() const = 0;

  // A batch and its runs, atomically (all queued, or none). Returns the batch id; run ids in order in *run_ids.
  virtual StatusOr<std::int64_t> SubmitBatch(const std::string& submitter, const std::string& name,
                                             const std::string& batch_spec_json, std::vector<RunRecord> runs,
                                             std::vector<std::int64_t>* run_ids) = 0;

  // Queue: atomically picks the queued run with the highest priority, then the oldest (lowest id), whose
  // bench_kind equals `bench_kind` (or is empty) and whose bench_name is empty or equals `bench_name`; marks it
  // running on bench_name. nullopt when none is waiting.
  virtual StatusOr<std::optional<RunRecord>> ClaimNext(const std::string& bench_kind,
                                                       const std::string& bench_name) = 0;
  virtual Status SetProgress(std::int64_t run_id, double progress) = 0;
  // Final state with metrics (written in the same transaction). FailedPrecondition if the run is not running.
  virtual Status Finish(std::int64_t run_id, RunStatus final_status, const std::string& reason,
                        const std::vector<Metric>& metrics) = 0;
  // Cancels a queued run at once (returns kCancelled); for a running run records the request and returns
  // kRunning (the worker stops it and calls Finish(kCancelled)); FailedPrecondition for finished runs.
  virtual StatusOr<RunStatus> RequestCancel(std::int64_t run_id, const std::string& reason) = 0;
  virtual StatusOr<bool> CancelRequested(std::int64_t run_id) = 0;
  // On server start: every run still marked running becomes interrupted; those with requeue_on_interrupt
  // are queued again (keeping their id, priority and age), unless this was their third interruption: a run
  // that keeps taking the server down is failed with the reason (a poison run). Returns how many were
  // interrupted.
  virtual StatusOr<int> RecoverAfterCrash() = 0;

  virtual StatusOr<RunRecord> GetRun(std::int64_t run_id) = 0;
  virtual StatusOr<std::vector<RunRecord>> ListRuns(const RunFilter& filter) = 0;
  virtual StatusOr<std::vector<StatusChange>> History(std::int64_t run_id) = 0;
  virtual StatusOr<std::vector<Metric>> GetMetrics(std::int64_t run_id) = 0;
  virtual StatusOr<std::int64_t> CountQueued(const std::string& submitter) = 0;
  // Bytes the stored trace chunks of `submitter`'s runs take (as stored: compressed since schema v4).
  virtual StatusOr<std::int64_t> StoredTraceBytes(const std::string& submitter) = 0;

  // Traces: chunks appended in index order while the run executes; read back in order.
  virtual Status AppendTraceChunk(std::int64_t run_id, const TraceChunk& chunk) = 0;
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

// The batch a baseline's source names when its runs are in the local store ("local batch 12", "suite ci (local
// batch 12, seed 1)"), else 0. benchctl writes these sources (benchctl/regress_commands.cc).
std::int64_t LocalBatchOfBaselineSource(const std::string& source);

}  // namespace vb::db
