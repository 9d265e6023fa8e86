// Where queued runs stand and when they should end (docs/lab.md, "The queue"): the one estimate `benchctl
// queue` and the web dashboard show. Position is the claim order (priority, then age; aging not counted).
// A queued run's ETA is the bench time left of the running runs plus that of the queued runs up to and
// including it, spread over the live benches. A running run's ETA is its wall time left, from its progress so
// far. Bench time is wall time on paced and hardware benches; an unpaced emulator runs faster, so the estimate
// is an upper bound there.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "common/run_status.h"

namespace vb {

struct QueueRunInfo {
  std::int64_t id = 0;
  RunStatus status = RunStatus::kQueued;
  std::int32_t priority = 0;
  double duration_s = 0.0;       // the spec's (0 = unknown)
  double progress = 0.0;         // 0..1
  double started_unix_s = 0.0;   // running runs
};

struct QueueEstimate {
  int position = 0;              // 1 = claimed next
  double eta_s = -1.0;           // < 0: unknown
};

// Queued runs only (running runs count as work ahead of them).
std::map<std::int64_t, QueueEstimate> EstimateQueue(const std::vector<QueueRunInfo>& runs, int live_benches);
// A running run's wall time left; < 0 before any progress.
double RunningEta_s(const QueueRunInfo& run, double now_unix_s);

}  // namespace vb
