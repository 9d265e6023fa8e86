// The nightly regression (config "nights", docs/regress.md): a thread that sleeps until the next cron fire
// (UTC), queues each bench's health check (server/health_check.h) as a batch "health:YYYY-MM-DD", submits the
// suite's runs as one batch "night:YYYY-MM-DD" (tags "night", "night:YYYY-MM-DD" and the night's number,
// submitter "nights"), waits for them, compares them with the baseline (regress::Compare, the rule of
// `benchctl regress`) and stores the verdict in the regressions table as a night.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"
#include "runs/admit.h"
#include "server/bench_twin.h"
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

  // benches: the configured benches; those with a "health" block get their health check before each night's
  // suite (server/health_check.h).
  NightScheduler(NightsSetup setup, std::vector<runs::BenchSetup> benches, StorePool* pool, SubmitFn submit,
                 ClockFn clock = {});
  ~NightScheduler();
  NightScheduler(const NightScheduler&) = delete;
  NightScheduler& operator=(const NightScheduler&) = delete;

  // Starts the thread; nights_now > 0: that many nights at once, back to back, dated the nights_now days ending
  // today (the --run-night-now and --simulate-nights hooks: a lab lives 60 nights in minutes), then the schedule.
  void Start(int nights_now);
  // Wakes the thread and joins it. A night in progress is abandoned (its runs stay in the queue; nothing is
  // stored for it).
  void Stop();

  // One night, blocking: fire_unix_s names the date. Returns the stored regression id, or the reason nothing
  // was stored (stopped). Failures of the night itself are stored with verdict "error".
  StatusOr<std::int64_t> RunNight(double fire_unix_s);

 private:
  void Loop(int nights_now);
  // The lab's number for the night `date`: 1 + the distinct other nights stored (the newest 1000).
  StatusOr<int> NightNumber(const std::string& date);
  // The bench twin's part of a night (server/bench_twin.h): each checked bench's values and flags into its
  // `health` entry, and a regressed night's cause into j["cause"] (against the valve of the night the baseline was
  // measured on, and its code: the baseline's batch when its source names one here, else that night's suite).
  void TwinNight(const std::string& date, const regress::RegressResult& r,
                 const std::map<std::string, experiment::ExperimentSpec>& case_specs,
                 const std::map<std::string, std::vector<std::string>>& case_benches, const CaseBuilds& case_builds,
                 const regress::Baseline& baseline, regress::Json* health, regress::Json* j);
  // The code the baseline was measured with (server/bench_twin.h BaselineCode); empty with the reason logged when
  // its runs are not in the store. A batch its source names counts only if its runs summarise to the baseline
  // (regress::BaselineNotOfRuns); otherwise the night rule, the mismatch said first in `from`. The builds: the own
  // batch's; under the night rule that night's, for the cases it compared with this baseline and reproduced.
  BaselineCode BaselineCodeOf(const regress::Baseline& baseline, const std::map<std::string, StoredCheck>& suites);
  StatusOr<std::int64_t> SaveNight(const std::string& date, std::int64_t batch_id, const std::string& verdict,
                                   const std::string& result_json, double finished_unix_s);

  NightsSetup setup_;
  // The benches whose health check tonight queues: this host's, and in a lab every live host's that has one.
  std::vector<runs::BenchSetup> CheckedBenches();
  std::vector<runs::BenchSetup> benches_;
  StorePool* pool_;
  BenchTwins twins_{pool_};
  SubmitFn submit_;
  ClockFn clock_;
  std::thread thread_;
  StopSignal stop_signal_{[this] { return clock_(); }};
};

}  // namespace vb::server
