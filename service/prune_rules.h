// The service's prune rules (docs/store.md "Retention"): Store::Prune with the service's own protection added,
// the one path the admin PruneRuns RPC and the server's retention scheduler (server/retention.h) both take.
#pragma once

#include <string>

#include "common/status.h"
#include "db/records.h"
#include "regress/compare.h"
#include "service/service.h"
#include "service/settings.h"

namespace vb::server {

// Store::Prune on the service's store with the service's own protection added: the batch the nights' baseline
// file was taken from stays. Refuses (deleting nothing) when that file is configured but cannot be read.
StatusOr<db::PruneResult> PruneWithServerRules(StorePool* pool, const NightsSetup& nights, db::PruneRequest req);

// A baseline JSON file as `benchctl baseline show --json` writes it (nights.baseline_file).
StatusOr<regress::Baseline> LoadBaselineFile(const std::string& path);

}  // namespace vb::server
