// For tests only: the lease a run's current attempt holds, read back from the store, so that a test which
// writes for a run it claimed earlier (or never claimed) need not carry the RunRecord around. Fencing itself is
// tested with explicit leases (tests/db/lab_store_test.cc).
#pragma once

#include <cstdint>

#include "db/records.h"

namespace vb::db::testing {

template <typename StorePtr>
Lease CurrentLease(const StorePtr& store, std::int64_t run_id) {
  auto run = store->GetRun(run_id);
  return Lease{run_id, run.ok() ? run->fence : 0};
}

}  // namespace vb::db::testing
