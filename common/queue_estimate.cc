#include "common/queue_estimate.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace vb {

bool CanClaim(const QueueBench& b, const QueueRunInfo& r) {
  if (!b.live) return false;
  if (b.any_class || r.bench_class.empty()) return r.bench_name.empty() || r.bench_name == b.name;
  return b.bench_class == r.bench_class && (r.bench_name.empty() || r.bench_name == b.name);
}

std::map<std::int64_t, QueueEstimate> EstimateQueue(const std::vector<QueueRunInfo>& runs,
                                                    const std::vector<QueueBench>& benches) {
  constexpr double kUnknown = std::numeric_limits<double>::quiet_NaN();
  // When each live bench is free: after the bench time left of the run it is running (NaN: unknown).
  std::vector<double> free_at(benches.size(), 0.0);
  for (const auto& r : runs) {
    if (r.status != RunStatus::kRunning) continue;
    for (std::size_t b = 0; b < benches.size(); ++b) {
      if (!benches[b].live || benches[b].name != r.bench_name) continue;
      free_at[b] += r.duration_s > 0 ? std::max(0.0, r.duration_s * (1.0 - r.progress)) : kUnknown;
      break;
    }
  }
  std::vector<const QueueRunInfo*> queued;
  for (const auto& r : runs)
    if (r.status == RunStatus::kQueued) queued.push_back(&r);
  std::stable_sort(queued.begin(), queued.end(), [](const QueueRunInfo* a, const QueueRunInfo* b) {
    return a->priority != b->priority ? a->priority > b->priority : a->id < b->id;
  });
  std::map<std::int64_t, QueueEstimate> out;
  for (std::size_t k = 0; k < queued.size(); ++k) out[queued[k]->id] = {static_cast<int>(k) + 1, -1.0};

  // Replay the claims: the bench free first claims the first unclaimed run it can run. Each bench's cursor
  // only moves forward (runs are claimed, never returned), so this is O(runs x benches).
  std::vector<bool> claimed(queued.size(), false);
  std::vector<std::size_t> cursor(benches.size(), 0);
  std::vector<bool> done(benches.size(), false);
  for (std::size_t b = 0; b < benches.size(); ++b) done[b] = !benches[b].live;
  for (;;) {
    // The bench free first (an unknown time counts as last: its claims have no ETA).
    auto key = [&](std::size_t b) {
      return std::isnan(free_at[b]) ? std::numeric_limits<double>::infinity() : free_at[b];
    };
    std::size_t pick = benches.size();
    for (std::size_t b = 0; b < benches.size(); ++b)
      if (!done[b] && (pick == benches.size() || key(b) < key(pick))) pick = b;
    if (pick == benches.size()) break;
    std::size_t& c = cursor[pick];
    while (c < queued.size() && (claimed[c] || !CanClaim(benches[pick], *queued[c]))) ++c;
    if (c == queued.size()) {
      done[pick] = true;  // nothing left this bench can run
      continue;
    }
    claimed[c] = true;
    const double d = queued[c]->duration_s;
    free_at[pick] = d > 0 && !std::isnan(free_at[pick]) ? free_at[pick] + d : kUnknown;
    if (!std::isnan(free_at[pick])) out[queued[c]->id].eta_s = free_at[pick];
  }
  return out;
}

std::map<std::int64_t, QueueEstimate> EstimateQueue(const std::vector<QueueRunInfo>& runs, int live_benches) {
  // Benches that can each run everything; the running runs are spread over them in order.
  std::vector<QueueBench> benches;
  for (int b = 0; b < live_benches; ++b) benches.push_back({"bench" + std::to_string(b), "", true, true});
  std::vector<QueueRunInfo> placed = runs;
  int next = 0;
  for (auto& r : placed)
    if (r.status == RunStatus::kRunning && live_benches > 0) r.bench_name = benches[next++ % live_benches].name;
  for (auto& r : placed)
    if (r.status == RunStatus::kQueued) r.bench_name.clear();
  return EstimateQueue(placed, benches);
}

double RunningEta_s(const QueueRunInfo& r, double now_unix_s) {
  if (r.status != RunStatus::kRunning || r.started_unix_s <= 0.0 || r.progress <= 0.0) return -1.0;
  const double elapsed = std::max(0.0, now_unix_s - r.started_unix_s);
  return elapsed * (1.0 - r.progress) / r.progress;
}

}  // namespace vb
