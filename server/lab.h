// This server as one host of a lab (config "lab"; docs/lab.md): a thread that keeps the host's registration and
// leases alive and watches the runs its benches execute.
//   - every heartbeat_s: Heartbeat (the host row with its benches, and the leases of the runs its benches are
//     executing renewed to now + lease_ttl_s), then RequeueLapsed (any host re-queues the runs of hosts that
//     stopped heartbeating; after the store was unavailable, only one lease TTL after it is back);
//   - the store unavailable: logged once when it begins and once, with its duration, when it ends; the thread
//     goes on trying (timeouts bound every call: db/pg_conn.h);
//   - every 100 ms, for each bench's run in progress (runs::WatchRuns, runs/watch.h, as a local service's relay):
//     a cancel requested through the store (CancelRun on another host) stops it; its progress is written to the
//     store every 0.5 s so watchers on other hosts follow it; a progress write refused as stale (the lease lapsed,
//     the run is someone else's now) stops it too.
// Nothing here touches the control loop: it sets the run's cancel flag, as CancelRun does.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "runs/monitor.h"
#include "runs/spool.h"
#include "runs/store_faults.h"
#include "runs/worker.h"
#include "server/config.h"
#include "service/lab_benches.h"
#include "server/stop_signal.h"
#include "valvebench/v1/api.pb.h"

namespace vb::server {


class LabHost {
 public:
  LabHost(LabSetup setup, std::string db_path, std::string benches_json, runs::Registry* registry,
          const std::vector<std::unique_ptr<runs::Worker>>* workers);
  ~LabHost();
  LabHost(const LabHost&) = delete;
  LabHost& operator=(const LabHost&) = delete;

  // The first heartbeat happens before Start returns (so `benches` on any host lists this one at once); an error
  // there (the database refuses it) is returned and no thread is started.
  Status Start();
  void Stop();
  // Before Start(): the host's spool, whose uploading runs' leases the heartbeat renews too.
  void set_spool(const runs::Spool* spool) { spool_ = spool; }

 private:
  void Loop();
  Status Beat(db::Store* store);
  void WatchRuns(db::Store* store, bool write_progress);

  LabSetup setup_;
  std::string db_path_;
  std::string benches_json_;
  double started_unix_s_;
  runs::Registry* registry_;
  const std::vector<std::unique_ptr<runs::Worker>>* workers_;
  const runs::Spool* spool_ = nullptr;
  std::unique_ptr<db::Store> store_;
  runs::FaultLog faults_{"lab"};  // the store's faults as this thread meets them, logged once each
  // After a fault, lapsed leases are re-queued only from here on (one lease TTL after the store came back).
  std::chrono::steady_clock::time_point reap_after_{};
  std::thread thread_;
  StopSignal stop_;
};

}  // namespace vb::server
