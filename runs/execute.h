// Execute: one claimed run from its stored spec to its final state in the store, on the bench its setup
// describes. The same function for the server's workers and benchctl's local mode:
//   1. parse the stored spec; on an emulated bench with a configured model, that model is the plant (it
//      stands in for hardware, and a spec cannot change hardware); the spec's perturbations still apply;
//   2. build the experiment and open the bench, behind the safety interlocks (current, duty, on-time, coil
//      temperature, watchdog) unless the setup has none;
//   3. run it (Runner), with cancel and progress through a RunMonitor registered for watchers; the trace
//      streams to the store in chunks while it runs (docs/store.md, "Traces while the run executes"), so a
//      run's memory does not grow with its length and a watcher elsewhere sees the chunks as they land;
//   4. finish the run with its status, reason, finite metrics and what executing it measured (wall time, samples,
//      a paced loop's ticks, overruns and jitter), in the one write that ends the run: after the loop, never in it.
// Every store write on the way survives a store that is unavailable for a while (ExecuteContext::retry): a
// chunk that cannot be written is kept and written later; the result is retried until written, or, past the
// policy's bound, dropped: the run is then left running under a lease nobody renews, so it lapses and the lab
// re-runs it. A run is never failed because the store could not be reached.
// A run stopped by `stop` (server shutdown) is not finished: it stays running in the store, and the next
// start marks it interrupted and re-queues it (docs/decisions.md, "A server stopped mid-run").
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>

#include "db/store.h"
#include "experiment/runner.h"
#include "runs/bench_setup.h"
#include "runs/monitor.h"
#include "runs/spool.h"
#include "runs/store_faults.h"

namespace vb::runs {

struct Outcome {
  std::int64_t run_id = 0;
  db::RunStatus status = db::RunStatus::kFailed;  // as recorded
  std::string reason;
  bool recorded = false;             // false: left running for recovery (stopped), or the store refused
  bool stale = false;                // the store refused a write as stale: the run is another attempt's now
  bool released = false;             // the store stayed unavailable: the result was dropped, the run is left to
                                     // lapse and be re-run (never failed for a transport error)
  // The result is written to the host's spool and waits there for the store (ExecuteContext::spool): the
  // uploader writes it when the store takes it (or the next start does); the run is neither released nor failed.
  bool spooled = false;
  bool bench_fault = false;          // it failed at the bench: the bench could not be opened or an interlock
                                     // tripped (the Worker marks the bench faulted; decided here, not from text)
  experiment::RunSummary summary;    // empty when the run never started (bad spec, bench not there)
  experiment::Trace trace;           // what was recorded, when ExecuteContext::keep_trace (it is in the store)
};

struct ExecuteContext {
  Registry* registry = nullptr;                 // where watchers find the run; nullptr: nobody watches
  const std::atomic<bool>* stop = nullptr;      // shutdown: stop the run and leave it for recovery
  std::atomic<experiment::RunMonitor*>* current_monitor = nullptr;  // published while the run executes
  bool keep_trace = false;                      // also keep the whole trace in Outcome::trace (memory grows)
  // Held while current_monitor is cleared (the monitor is destroyed right after): whoever sets the published
  // monitor's cancel flag from another thread holds it too, so it never writes to a monitor that is gone.
  std::mutex* current_monitor_mu = nullptr;
  // Called once the experiment has ended, before its result is written: from then on the run is not executing
  // (its lease is no longer renewed by the host's heartbeat, and no progress is written for it).
  std::function<void()> ended;
  // Store writes on the run's path (trace chunks, progress, the result) that fail transiently are retried with
  // this policy (its give_up_s bounds how long a result is kept when the store is unavailable; its stop is
  // `stop`'s); the faults are logged through `faults` (nullptr: not logged). docs/lab.md, "When the database
  // fails".
  RetryPolicy retry;
  FaultLog* faults = nullptr;
  // The host's spool (runs/spool.h): when set, the trace's chunks and the result go to a journal on the local
  // disk and the spool's uploader writes them to the store; the trace stream never waits on the store. A spool
  // that cannot be written stops the run (safe state) and fails it with the reason, as a bench fault. The wait
  // for the result to land is retry.give_up_s; past it the result stays in the spool (Outcome::spooled).
  Spool* spool = nullptr;
};

Outcome Execute(db::Store* store, const db::RunRecord& run, const BenchSetup& setup, const ExecuteContext& ctx);

// A write the store refused because the lease no longer holds the run (db::Lease): the run was re-queued or
// re-assigned while this attempt ran. The attempt stops writing, logs it, and does not retry (docs/lab.md).
// Decided by the status code (db::ClassifyWrite), not its text.
bool IsStaleWrite(const Status& st);

// The metrics a run records: the finite ones of experiment::MetricList, in its order.
std::vector<db::Metric> RecordedMetrics(const experiment::Metrics& metrics);
// What a run records of its execution (wall time, samples, ticks, and the loop statistics of a paced loop: the
// loop is taken as paced when it counted paced ticks), written with its final state.
db::ExecutionRecord RecordedExecution(const experiment::RunSummary& summary);

}  // namespace vb::runs
