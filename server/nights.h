// The nightly regression (config "nights", docs/regress.md): a thread that sleeps until the next cron fire
// (UTC), submits the suite's runs as one batch "night:YYYY-MM-DD" (tags "night" and "night:YYYY-MM-DD",
// submitter "nights"), waits for them, compares them with the baseline (regress::Compare, the rule of
// `benchctl regress`) and stores the verdict in the regressions table as a night.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"
#include "runs/admit.h"
#include "server/config.h"
#include "server/stop_signal.h"
#include "service/service.h"

namespace vb::server {

class NightScheduler {
 public:
  // Admits and queues a submission (BenchServiceImpl::Queue: runs::Admit and runs::Enqueue, the checks and
  // limits of SubmitBatch); returns the batch and run ids.
  using SubmitFn = std::function<StatusOr<runs::Queued>(const runs::Submission&)>;
  // Wall clock in unix seconds; injectable for tests.
  using ClockFn = std::function<double()>;

  NightScheduler(NightsSetup setup, StorePool* pool, SubmitFn submit, ClockFn clock = {});
  ~NightScheduler();
  NightScheduler(const NightScheduler&) = delete;
  NightScheduler& operator=(const NightScheduler&) = delete;

  // Starts the thread; run_now: one night at once (the --run-night-now test hook), then the schedule.
  void Start(bool run_now);
  // Wakes the thread and joins it. A night in progress is abandoned (its runs stay in the queue; nothing is
  // stored for it).
  void Stop();

  // One night, blocking: fire_unix_s names the date. Returns the stored regression id, or the reason nothing
  // was stored (stopped). Failures of the night itself are stored with verdict "error".
  StatusOr<std::int64_t> RunNight(double fire_unix_s);

 private:
  void Loop(bool run_now);
  StatusOr<std::int64_t> SaveNight(const std::string& date, std::int64_t batch_id, const std::string& verdict,
                                   const std::string& result_json, double finished_unix_s);

  NightsSetup setup_;
  StorePool* pool_;
  SubmitFn submit_;
  ClockFn clock_;
  std::thread thread_;
  StopSignal stop_signal_{[this] { return clock_(); }};
};

}  // namespace vb::server
