// The records the results store reads and writes (the interface: db/store.h): a run and the lease on its current
// attempt, a claim, a lab's host, a refused stale write, status changes, metrics, trace chunks, a listing's
// filter, order and cursor, baselines and regression results, retention's request and outcome; and the small
// helpers on them that callers and both engines share (LeaseOf, BenchClaim, ClassifyWrite, the baseline sources'
// batch parsers). Plain values, no database: code that handles runs without calling a store needs only this.
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/run_key.h"
#include "common/run_status.h"
#include "common/status.h"

namespace vb::db {

// The statuses and their names are common/run_status.h's (the store keeps the names in its status columns).
using vb::ParseRunStatus;
using vb::RunStatus;
using vb::RunStatusName;

// How a paced (realtime) run's loop kept its deadlines: hw::LoopStats as stored (schema v6).
struct LoopRecord {
  std::int64_t ticks = 0;           // paced ticks
  std::int64_t overruns = 0;        // ticks whose work ended after their deadline
  double jitter_p50_s = 0.0;        // wake-up lateness after the deadline
  double jitter_p99_s = 0.0;
  double jitter_max_s = 0.0;
};

// What executing a run measured on its host (experiment::RunSummary's numbers), written by Finish in the same
// transaction as the final state (schema v6), so whoever reads the run later, from any door or host, has them.
struct ExecutionRecord {
  double wall_s = 0.0;                  // wall-clock time the experiment took
  double simulated_s = 0.0;             // experiment time covered (where a stopped run got to)
  std::int64_t samples = 0;             // samples recorded
  std::int64_t control_ticks = 0;       // ticks of the control loop
  bool metrics_from_trajectory = false; // the metrics' source: the exact trajectory (emulator) or the samples
  std::optional<LoopRecord> loop;       // paced runs only: nullopt when the loop was not paced
  // Which build executed it (runs::ThisBuild: "valvebench VERSION sha256:DIGEST"; schema v7), "" when not known:
  // every run finished before v7, and a process that could not read its own executable.
  std::string build;
};

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
  // The lab (docs/lab.md), schema v5: the attempt that holds the run (incremented by every claim; the fencing
  // token its writes carry), the host executing it, and when its lease lapses (0 = no lease: one machine).
  std::int64_t fence = 0;
  std::string host;
  double lease_expires_unix_s = 0.0;
  // Schema v6: what executing it measured; nullopt for a run that did not execute (queued, imported, a spec that
  // failed before the bench ran) or that finished before v6.
  std::optional<ExecutionRecord> execution;
};

// A claimed run's lease (docs/lab.md, "Leases and fencing"): the run and the attempt that holds it. Every write
// the executing host makes for the run carries it. The store refuses a write whose fence is not the run's
// current one, or for a run that is no longer running (the lease lapsed and the run was re-queued or
// re-assigned to another host), with FailedPrecondition starting "stale write", logs it and counts it.
struct Lease {
  std::int64_t run_id = 0;
  std::int64_t fence = 0;
};
inline Lease LeaseOf(const RunRecord& run) { return {run.id, run.fence}; }

// What ClaimNext claims for.
struct ClaimRequest {
  std::string bench_kind;        // the bench's class: runs asking for another kind are not claimed
  std::string bench_name;        // the claiming bench (required); runs asking for another bench are not claimed
  std::string host;              // the claiming host ("" = one machine, no lab)
  double lease_ttl_s = 0.0;      // > 0: the lease lapses this long after the claim or the last Heartbeat
  double aging_s = 0.0;          // > 0: a queued run's priority rises by 1 for every aging_s it has waited
};
// A claim on one machine: no host, no lease, no aging.
inline ClaimRequest BenchClaim(std::string bench_kind, std::string bench_name) {
  ClaimRequest r;
  r.bench_kind = std::move(bench_kind);
  r.bench_name = std::move(bench_name);
  return r;
}

// A server process sharing the store (docs/lab.md, "Hosts").
struct HostRecord {
  std::string name;              // unique in the lab
  std::string address;           // where its gRPC API listens (host:port), for people and other hosts
  std::string benches_json;      // its benches as a JSON array (name, kind, ...), written at every heartbeat
  double started_unix_s = 0.0;
  double heartbeat_unix_s = 0.0; // set by the store (its clock) at every Heartbeat
};

// A write the store refused because its lease was stale (StaleWrites()).
struct StaleWrite {
  std::int64_t run_id = 0;
  std::int64_t fence = 0;        // the writer's
  std::int64_t current_fence = 0;
  std::string host;              // the host that holds the run now ("" = none: re-queued)
  std::string what;              // "progress", "trace chunk 3", "finish done", ...
  double at_unix_s = 0.0;
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

// The order of a run listing (db/run_query.h parses the API's order_by). Ties are broken by id in the same
// direction, so every order is total and a keyset cursor pages through it.
enum class RunSortKey {
  kId,
  kSubmitted,
  kStarted,
  kFinished,
  kDuration,    // finished - started for a run that started and finished, else 0
  kName,        // RunKey::DisplayName(), byte order (both engines)
  kStatus,      // lifecycle order: queued, running, interrupted, done, failed, cancelled
  kBench,       // bench_name
  kController,
  kSubmitter,
};
struct RunOrder {
  RunSortKey key = RunSortKey::kId;
  bool desc = false;
  bool operator==(const RunOrder&) const = default;
};
// Keyset paging: the listing continues after the run whose sort key had this value (number for the numeric keys
// and kStatus's rank, text for the text keys) and this id.
struct RunCursor {
  double number = 0.0;
  std::string text;
  std::int64_t id = 0;
};

struct RunFilter {
  std::optional<RunStatus> status;
  std::string tag;                  // runs carrying this tag
  std::int64_t batch_id = 0;        // 0 = any
  std::string controller;
  std::string bench_name;
  std::string submitter;
  std::string name;                 // runs whose name contains this text (ASCII case-insensitive)
  double submitted_after_unix_s = 0.0;
  double submitted_before_unix_s = 0.0;  // 0 = no bound
  std::int64_t after_id = 0;        // runs with id > after_id (a filter: whatever the order)
  RunOrder order;                   // default: by id, oldest first (the API's default is "submitted desc")
  std::optional<RunCursor> after;   // paging in `order`: the runs after this one (CursorAfter, page tokens)
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

// What a writer does with a store error, decided by its code alone (never its text; docs/lab.md, "When the
// database fails").
enum class WriteFault {
  kNone,       // it worked
  kTransient,  // Unavailable (the database cannot be reached or did not answer in time) or Aborted
               // (serialization failure, deadlock, lock timeout): the same write may succeed later; retry
  kFenced,     // FailedPrecondition or NotFound for a write carrying a Lease: a stale write, the run is no
               // longer this attempt's (re-queued, re-assigned, finished); stop writing for it, never retry
  kPermanent,  // anything else: bad data or a bug; retrying cannot help
};
WriteFault ClassifyWrite(const Status& st);

// The batch a baseline's source names when its runs are in the local store ("local batch 12", "suite ci (local
// batch 12, seed 1)"), else 0. benchctl writes these sources (benchctl/regress_commands.cc).
std::int64_t LocalBatchOfBaselineSource(const std::string& source);
// The batch a baseline taken on a server names ("server lab:50051 batch 12", "suite ci (server lab:50051 batch
// 12, seed 1)"), else 0: what the server's retention protects for its nights' baseline file (server/retention.cc).
// Both parsers are in db/prune_plan.cc, beside the rules that use them.
std::int64_t ServerBatchOfBaselineSource(const std::string& source);

}  // namespace vb::db
