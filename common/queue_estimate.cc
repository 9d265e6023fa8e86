#include "common/queue_estimate.h"

#include <algorithm>

namespace vb {

std::map<std::int64_t, QueueEstimate> EstimateQueue(const std::vector<QueueRunInfo>& runs, int live_benches) {
  double ahead_s = 0.0;
  bool known = live_benches > 0;
  for (const auto& r : runs)
    if (r.status == RunStatus::kRunning) {
      if (r.duration_s <= 0) known = false;
      ahead_s += std::max(0.0, r.duration_s * (1.0 - r.progress));
    }
  std::vector<const QueueRunInfo*> queued;
  for (const auto& r : runs)
    if (r.status == RunStatus::kQueued) queued.push_back(&r);
  std::stable_sort(queued.begin(), queued.end(), [](const QueueRunInfo* a, const QueueRunInfo* b) {
    return a->priority != b->priority ? a->priority > b->priority : a->id < b->id;
  });
  std::map<std::int64_t, QueueEstimate> out;
  for (std::size_t k = 0; k < queued.size(); ++k) {
    if (queued[k]->duration_s <= 0) known = false;
    ahead_s += std::max(0.0, queued[k]->duration_s);
    out[queued[k]->id] = {static_cast<int>(k) + 1, known ? ahead_s / live_benches : -1.0};
  }
  return out;
}

double RunningEta_s(const QueueRunInfo& r, double now_unix_s) {
  if (r.status != RunStatus::kRunning || r.started_unix_s <= 0.0 || r.progress <= 0.0) return -1.0;
  const double elapsed = std::max(0.0, now_unix_s - r.started_unix_s);
  return elapsed * (1.0 - r.progress) / r.progress;
}

}  // namespace vb
