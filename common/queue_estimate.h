// Where queued runs stand and when they should end (docs/lab.md, "The queue"): the one estimate `benchctl
// queue`, the web dashboard and Python show (service/queue_service.cc computes it once for all of them).
// Position is the claim order (priority, then age; aging not counted).
//
// The ETA replays the claims: a bench, when free, claims the first run in claim order that it can run (its
// class: the model preset for the emulator, the kind for hardware, as db::BenchClaim matches; and the bench the
// spec names, if any). A bench is free once its running run's bench time is over; a queued run ends at the
// time its bench was free plus its duration. So a run only waits for the benches that can take it: a
// taghizadeh2009 run behind three lunge2013 runs on a lab with one bench of each is not spread over both.
// A running run's ETA is its wall time left, from its progress so far. Bench time is wall time on paced and
// hardware benches; an unpaced emulator runs faster, so the estimate is an upper bound there.
#pragma once

#include <cstdint>
#include <map>
#include <string>
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
  // Which benches may claim it: the class it was admitted for ("emulated:taghizadeh2009", "hid"; "" = any) and
  // the bench the spec asks for ("" = any of the class). A running run: the bench running it.
  std::string bench_class;
  std::string bench_name;
};

// A bench that claims runs. any_class: the local emulator (benchctl run --local), which takes every spec.
struct QueueBench {
  std::string name;
  std::string bench_class;
  bool live = true;
  bool any_class = false;
};

struct QueueEstimate {
  int position = 0;              // 1 = claimed next
  double eta_s = -1.0;           // < 0: unknown (no live bench can run it, or a duration ahead of it is unknown)
};

// True when `bench` would claim `run` (class and requested name).
bool CanClaim(const QueueBench& bench, const QueueRunInfo& run);

// Queued runs only (running runs keep their benches busy).
std::map<std::int64_t, QueueEstimate> EstimateQueue(const std::vector<QueueRunInfo>& runs,
                                                    const std::vector<QueueBench>& benches);
// `live_benches` benches that can each run everything.
std::map<std::int64_t, QueueEstimate> EstimateQueue(const std::vector<QueueRunInfo>& runs, int live_benches);
// A running run's wall time left; < 0 before any progress.
double RunningEta_s(const QueueRunInfo& run, double now_unix_s);

}  // namespace vb
