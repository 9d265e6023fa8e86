#include "runs/query.h"

namespace vb::runs {

StatusOr<std::vector<db::RunRecord>> ListBatch(db::Store* store, std::int64_t batch_id) {
  db::RunFilter f;
  f.batch_id = batch_id;
  f.limit = 1000;
  std::vector<db::RunRecord> out;
  for (;;) {
    auto page = store->ListRuns(f);
    if (!page.ok()) return page.status();
    out.insert(out.end(), std::make_move_iterator(page->begin()), std::make_move_iterator(page->end()));
    if (static_cast<std::int32_t>(page->size()) < f.limit) break;
    f.after_id = out.back().id;
  }
  if (out.empty()) return Status::NotFound("batch " + std::to_string(batch_id) + " not found");
  return out;
}

StatusOr<std::vector<db::RunRecord>> GetRuns(db::Store* store, const std::vector<std::int64_t>& run_ids) {
  std::vector<db::RunRecord> out;
  for (auto id : run_ids) {
    auto r = store->GetRun(id);
    if (!r.ok()) return r.status();
    out.push_back(std::move(*r));
  }
  return out;
}

StatusOr<experiment::Comparison> CompareStored(db::Store* store, const std::vector<db::RunRecord>& runs) {
  std::vector<experiment::RunRecord> records;
  for (const auto& r : runs) {
    experiment::RunRecord rec;
    rec.key = r.key;
    rec.run_id = r.id;
    rec.controller = r.controller;
    rec.ok = r.status == db::RunStatus::kDone;
    auto metrics = store->GetMetrics(r.id);
    if (!metrics.ok()) return metrics.status();
    for (const auto& m : *metrics) rec.metrics[m.name] = m.value;
    records.push_back(std::move(rec));
  }
  return experiment::Compare(records);
}

}  // namespace vb::runs
