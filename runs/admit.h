// Admit: whether a submission may be queued, and the runs it becomes. The same function for the server's
// SubmitRun/SubmitBatch, the nights scheduler and benchctl's local mode; only the policy differs (the
// server's configured limits and benches; the local emulator, which takes any spec).
//   1. each spec within the size limit;
//   2. expanded (variants, sweeps, repeats) into runs with their RunKey, within the run-count limit;
//   3. each run built (every field validated, errors name it), within the duration and recording-rate limits
//      and the trace's memory budget;
//   4. each run matched to a bench that can run it (class, requested name, capabilities): decided here, at
//      submission, never at run time;
// then Enqueue() checks the submitter's queued-run limit and stores the batch in one transaction.
// Refusals: InvalidArgument (bad spec), ResourceExhausted (a limit), FailedPrecondition (no capable bench);
// "run k (name): " in front when a submission has several runs.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "db/store.h"
#include "experiment/spec.h"
#include "runs/bench_setup.h"

namespace vb::runs {

struct Limits {
  std::uint64_t max_spec_bytes = std::numeric_limits<std::uint64_t>::max();
  double max_duration_s = std::numeric_limits<double>::infinity();
  double max_record_rate_Hz = std::numeric_limits<double>::infinity();
  std::uint64_t max_queued_runs_per_user = std::numeric_limits<std::uint64_t>::max();
  std::uint64_t max_runs_per_submission = 100'000;
  // The size of a run's trace (samples x experiment::Trace::kBytesPerSample). The trace streams to the store
  // in chunks while the run executes (a run's memory stays a few blocks), so this bounds what one run may
  // write and what reading it back whole (an export, benchctl run --trace-csv) takes.
  double max_trace_bytes_per_run = std::numeric_limits<double>::infinity();
  // Disk a submitter's stored traces may take: Enqueue refuses a submission when what the user's traces take
  // now plus the new runs' traces counted uncompressed (an upper bound: stored traces are compressed) would
  // exceed it.
  double max_disk_bytes_per_user = std::numeric_limits<double>::infinity();
};

// The local mode's trace budget: a quarter of this machine's physical memory.
double LocalTraceBudgetBytes();

struct Policy {
  Limits limits;
  std::vector<BenchSetup> benches;  // what runs may be matched to
};

struct Submission {
  std::string submitter;
  std::string batch_name;
  std::vector<experiment::ExperimentSpec> specs;
  // Empty, or one per spec: specs already expanded elsewhere (a regression suite's runs) keep this identity;
  // each must then be a single run.
  std::vector<RunKey> keys;
  std::string batch_json;            // what the batch records as submitted; "" = the spec, when there is one
};

struct Admitted {
  std::string submitter;
  std::string batch_name;
  std::string batch_json;            // the submitted spec verbatim when there is one, else empty
  std::vector<db::RunRecord> runs;   // queued in this order
  double trace_bytes_raw = 0.0;      // the runs' traces uncompressed (12 float64 channels per sample)
};

struct Queued {
  std::int64_t batch_id = 0;
  std::vector<std::int64_t> run_ids;
};

StatusOr<Admitted> Admit(const Submission& submission, const Policy& policy);
StatusOr<Queued> Enqueue(db::Store* store, Admitted admitted, const Policy& policy);

}  // namespace vb::runs
