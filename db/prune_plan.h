// Retention as a pure plan (docs/store.md, "Retention"): from the facts an engine reads in its transaction (every
// run's id, batch, name, status and finish time; what references batches) and the request, which runs go and
// which stay, and why. No database here: the rules are unit-tested on facts alone (tests/db/prune_plan_test.cc),
// and both engines (db/sqlite_store.cc, db/pg_store.cc) read the facts, call PlanPrune and execute the plan.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "db/records.h"

namespace vb::db {

// What an engine reads for a prune.
struct PruneFacts {
  struct Run {
    std::int64_t id = 0;
    std::int64_t batch_id = 0;
    std::string name;
    RunStatus status = RunStatus::kDone;
    double finished_unix_s = 0.0;
  };
  struct Regression {  // a regression result that names a batch of this store
    std::int64_t id = 0;
    std::int64_t batch_id = 0;
    std::string night;   // "" = not a night
    std::string suite;
    std::vector<std::int64_t> health_batches;  // a night's health checks (HealthBatchesOfNight)
  };
  struct Baseline {
    std::string name;
    std::int32_t version = 0;
    std::string source;  // LocalBatchOfBaselineSource() finds the batch it was taken from
  };
  std::vector<Run> runs;  // every run, in any order
  std::vector<Regression> regressions;
  std::vector<Baseline> baselines;
};

struct PrunePlan {
  PruneResult result;                     // deleted/kept with reasons, newer_kept, batches_deleted (trace_bytes: 0)
  std::vector<std::int64_t> doomed;       // the runs to delete, newest first
  std::vector<std::int64_t> empty_batches;  // batches all of whose runs are doomed, ascending
};

// The health-check batches a night's stored result references (server/nights.cc writes them as
// result_json's "health": [{"bench", "batch_id", ...}]): the bench twin identifies its anchor and a baseline's
// night again from those runs after a restart, and `benchctl health --recompute` reads them. Anything else
// (not JSON, no such array, a batch that is not a positive integer) gives none.
std::vector<std::int64_t> HealthBatchesOfNight(const std::string& result_json);

// The rules, in the order they are applied to each finished run (newest first by id): newer than the cutoff
// (kept, counted), in a referenced batch (kept), one of the newest keep_last finished runs (kept), else deleted.
// Queued, running and interrupted runs are always kept. The request must have passed checks::CheckPrune.
PrunePlan PlanPrune(const PruneFacts& facts, const PruneRequest& request);

}  // namespace vb::db
