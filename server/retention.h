// Retention (docs/store.md "Retention"): the server's one pruning path, used by the admin PruneRuns RPC and by
// the scheduler that applies the config's "retention" block at each cron fire (UTC; docs/server.md).
#pragma once

#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

#include "common/status.h"
#include "db/records.h"
#include "server/config.h"
#include "server/stop_signal.h"
#include "service/prune_rules.h"
#include "service/service.h"

namespace vb::server {


class RetentionScheduler {
 public:
  // Wall clock in unix seconds; injectable for tests.
  using ClockFn = std::function<double()>;

  RetentionScheduler(RetentionSetup setup, NightsSetup nights, StorePool* pool, ClockFn clock = {});
  ~RetentionScheduler();
  RetentionScheduler(const RetentionScheduler&) = delete;
  RetentionScheduler& operator=(const RetentionScheduler&) = delete;

  // Starts the thread: it sleeps until the next cron fire, prunes, and repeats.
  void Start();
  // Wakes the thread and joins it (a prune in progress finishes first: it is one store transaction).
  void Stop();

  // One prune, blocking: runs that finished more than older_than_days before fire_unix_s go. Logs what was
  // deleted and kept (counts, bytes).
  StatusOr<db::PruneResult> RunOnce(double fire_unix_s);

 private:
  void Loop();

  RetentionSetup setup_;
  NightsSetup nights_;
  StorePool* pool_;
  ClockFn clock_;
  std::thread thread_;
  StopSignal stop_signal_{[this] { return clock_(); }};
};

}  // namespace vb::server
