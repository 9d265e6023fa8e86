// Reading runs back: a batch's runs in id order, and the comparison of stored runs (experiment::Compare on
// their metrics, repeats grouped by RunKey::CaseName). One place for the server's CompareRuns, the nights
// and benchctl's local backend.
#pragma once

#include <cstdint>
#include <vector>

#include "db/store.h"
#include "experiment/compare.h"

namespace vb::runs {

// Every run of the batch (paged through the store); NotFound "batch N not found" when it has none.
StatusOr<std::vector<db::RunRecord>> ListBatch(db::Store* store, std::int64_t batch_id);
// The runs by id, in the order given; NotFound naming the first missing one.
StatusOr<std::vector<db::RunRecord>> GetRuns(db::Store* store, const std::vector<std::int64_t>& run_ids);

StatusOr<experiment::Comparison> CompareStored(db::Store* store, const std::vector<db::RunRecord>& runs);

}  // namespace vb::runs
