// One stored run as the gap diagnosis takes it: its conditions from its spec, its gate and current from its trace
// (the one decoder). For DiagnoseRuns and the server's bench twin (server/bench_twin.h).
#pragma once

#include <cstdint>

#include "common/status.h"
#include "db/store.h"
#include "gap/stored_runs.h"

namespace vb::server {

StatusOr<gap::StoredRun> LoadStoredRun(db::Store* store, std::int64_t id);

}  // namespace vb::server
