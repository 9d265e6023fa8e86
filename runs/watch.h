// The runs a host's workers are executing, watched through the store: the one relay between a run executing here
// and the processes that see it only through the store (other lab hosts; benchctl watch or cancel in another
// shell on a local store). For each worker's executing run:
//   - a cancel requested through the store (CancelRun answered by another process) stops it;
//   - with write_progress, its progress is written to the store under the worker's executing lease (the run
//     cannot end while it is written: a progress write never races the run's result, issue 30);
//   - a progress write refused as stale (the lease lapsed, another attempt holds the run now) stops this attempt.
// The store unavailable: the fault goes to `faults` (logged once when it begins and once when it ends) and the
// watch stops there; the next one tries again. Nothing here touches the control loop: it sets the run's cancel
// flag, as CancelRun does.
#pragma once

#include <memory>
#include <vector>

#include "db/store.h"
#include "runs/monitor.h"
#include "runs/store_faults.h"
#include "runs/worker.h"

namespace vb::runs {

void WatchRuns(db::Store* store, const std::vector<std::unique_ptr<Worker>>& workers, Registry* registry,
               bool write_progress, FaultLog* faults);

}  // namespace vb::runs
