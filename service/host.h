// One host of the service (issue 40): what valvebench-server and a local service (benchctl --local,
// service/local_service.h) both are, assembled once. Host::Start:
//   1. opens the store (and migrates it): its errors come out here, once;
//   2. recovers what an earlier process left, as the options say:
//      kInterruptRunning (a server): the spool's leftovers uploaded, then this host's runs still marked running
//        interrupted (dated with the spool's last sign of life) and re-queued (docs/lab.md, "The spool");
//      kCancelLeftOvers (a local service): runs of its benches left queued by an interrupted invocation are
//        cancelled (nobody will claim them); running ones may be another shell's, and are left alone;
//      kNone (a local service that only reads): nothing;
//   3. one runs::Worker per bench (in a lab: claiming as the host, with its lease TTL and aging; with the spool);
//   4. the store pool and the BenchService, hosted on the caller's builder (HostService: message limits, the
//      status interceptor, the call gate); the gRPC server is built and started.
// Run() then starts what executes runs: the spool's uploader, each worker's thread (runs::Worker::Start: claim and
// execute, a store that fails retried and logged once per fault) and, with watch_period_s, the relay that watches
// the executing runs through the store (runs::WatchRuns: cancels from other processes, progress, stale attempts
// stopped). Between Start and Run the caller may do what must come first (valvebench-server: the lab's first
// heartbeat).
//
// Layering (DESIGN.md): the host is in service/ because the local service, which is in service/ and which benchctl
// starts, is one; server/ (network, TLS, lab heartbeats, nights, retention, the web door) uses it from above.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"
#include "runs/monitor.h"
#include "runs/spool.h"
#include "runs/store_faults.h"
#include "runs/worker.h"
#include "service/service.h"
#include "service/settings.h"

namespace vb::server {

struct HostOptions {
  // A SQLite file or a postgresql:// URL: what the pool, the workers, the spool and the relay open.
  std::string store;
  // Benches, tokens, limits, the lab identity. Not owned: outlives the host.
  const ServiceSettings* settings = nullptr;
  enum class Recovery { kInterruptRunning, kCancelLeftOvers, kNone };
  Recovery recovery = Recovery::kInterruptRunning;
  // kInterruptRunning: the host's spool (runs/spool.h); "" = none (traces and results go to the store directly).
  std::string spool_dir;
  std::uint64_t spool_max_bytes = std::uint64_t{1} << 30;
  // Keep each executed run's whole trace in its Outcome (for on_outcome).
  bool keep_traces = false;
  // > 0: a relay thread watches the executing runs through the store this often (runs::WatchRuns), writing
  // their progress every progress_every-th time. 0: none (a lab server's LabHost does it with its heartbeat).
  double watch_period_s = 0.0;
  int progress_every = 10;
  // Called on a worker's thread with what each run it executed produced (its summary, and with keep_traces its
  // trace). Optional.
  std::function<void(runs::Outcome&)> on_outcome;
};

class Host {
 public:
  // Steps 1-4 above. The builder may already have ports and credentials; the host adds the service.
  static StatusOr<std::unique_ptr<Host>> Start(HostOptions options, grpc::ServerBuilder* builder);
  ~Host();
  Host(const Host&) = delete;
  Host& operator=(const Host&) = delete;

  // Starts the spool's uploader, the workers and the relay.
  void Run();
  // How the benches stop (they go to their safe state either way, and no worker claims again):
  //   kLeaveRunning: a run stopped this way stays marked running in the store; the next start (recovery)
  //     interrupts and re-queues it (a server's shutdown);
  //   kCancel: the run executing is cancelled and recorded so (a local service: nobody would resume it).
  enum class StopMode { kLeaveRunning, kCancel };
  void StopBenches(StopMode mode);
  // After StopBenches: stops the relay and the spool's uploader (what it has not uploaded stays on disk).
  void StopRest();

  grpc::Server* server() { return server_.get(); }
  BenchServiceImpl* service() { return service_.get(); }
  StorePool* pool() { return pool_.get(); }
  runs::Registry* registry() { return &registry_; }
  const std::vector<std::unique_ptr<runs::Worker>>& workers() const { return workers_; }
  runs::Spool* spool() { return spool_.get(); }
  // Runs found running at start and interrupted (kInterruptRunning).
  int interrupted_at_start() const { return interrupted_; }

 private:
  explicit Host(HostOptions options) : options_(std::move(options)) {}
  Status Init(grpc::ServerBuilder* builder);
  Status Recover(db::Store* store);
  void RelayLoop();

  HostOptions options_;
  runs::Registry registry_;  // before the spool and the workers, which use it
  std::unique_ptr<runs::Spool> spool_;
  std::vector<std::unique_ptr<runs::Worker>> workers_;
  std::unique_ptr<StorePool> pool_;
  std::unique_ptr<BenchServiceImpl> service_;
  std::unique_ptr<grpc::Server> server_;
  int interrupted_ = 0;
  std::atomic<bool> relay_stop_{false};
  std::thread relay_;
  runs::FaultLog relay_faults_{"relay"};
  bool benches_stopped_ = false;
  bool rest_stopped_ = false;
};

}  // namespace vb::server
