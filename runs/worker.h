// A worker: one bench and the queue. ClaimAndExecute() claims the next compatible queued run from the store
// (priority, then age) and executes it (runs/execute.h). The server starts one thread per bench that loops
// on it; benchctl's local mode is the same worker, in process, called until its batch is done.
#pragma once

#include <atomic>
#include <mutex>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <thread>

#include "db/store.h"
#include "runs/bench_setup.h"
#include "runs/execute.h"
#include "runs/monitor.h"
#include "runs/store_faults.h"

namespace vb::runs {

// How a worker claims (db::ClaimRequest): its host, the lease TTL and aging in a lab (docs/lab.md); all empty/0
// on one machine.
struct ClaimPolicy {
  std::string host;
  double lease_ttl_s = 0.0;
  double aging_s = 0.0;
  // How long a run's result (and kept trace chunks) is retried while the store is unavailable before it is
  // dropped and the run left to lapse and be re-run (docs/lab.md, "When the database fails").
  double hold_result_s = 120.0;
};

class Worker {
 public:
  // registry may be nullptr (nobody watches, nobody signals work: Start() is then not useful).
  Worker(BenchSetup setup, Registry* registry);
  ~Worker();
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  // Before Start(): claim as a host of a lab.
  void set_claim_policy(ClaimPolicy policy) { policy_ = std::move(policy); }
  // Stops the run in progress if it is still the attempt `lease` names (another host took it over, or its cancel
  // was requested through the store); true if it was.
  bool CancelIfCurrent(const db::Lease& lease);

  // One step on the calling thread: nullopt when no run is waiting for this bench.
  StatusOr<std::optional<Outcome>> ClaimAndExecute(db::Store* store);

  // A thread that opens the store at db_path and loops on ClaimAndExecute until Stop(): a store that cannot be
  // opened or claimed from is retried (every 0.2 s, or when work is signalled), the fault logged once when it
  // begins and once when it ends.
  void Start(std::string db_path);
  // Before Start(): called on the worker's thread with the outcome of each run it executed (its summary, and
  // with keep_traces its trace).
  void set_on_outcome(std::function<void(Outcome&)> on_outcome) { on_outcome_ = std::move(on_outcome); }
  // Stops claiming, stops a running experiment (safe state), joins. A run stopped this way stays marked
  // running in the store, so the next start marks it interrupted and re-queues it.
  void Stop();
  // Stops claiming and cancels the running experiment (safe state), which is recorded as cancelled, then joins:
  // for a process whose runs nobody would resume (a local service).
  void StopCancelling();

  const BenchSetup& setup() const { return setup_; }
  // Before Start(): the host's spool (runs/spool.h); nullptr (the default): the trace goes to the store directly.
  void set_spool(Spool* spool) { spool_ = spool; }
  // Keep each run's whole trace in its Outcome (benchctl's local mode, for --trace-csv): memory grows with it.
  void set_keep_traces(bool keep) { keep_traces_ = keep; }
  std::int64_t current_run() const { return current_run_.load(); }
  // Why the bench is faulted: its last run failed at the bench (it could not be opened, or an interlock
  // tripped), with that run's reason; "" once a run finishes normally again (docs/server.md, "Benches").
  std::string fault() const;
  // The lease of the run in progress (run_id 0 when none): its writes carry it (db::Lease).
  db::Lease current_lease() const { return {current_run_.load(), current_fence_.load()}; }
  // The lease of the run whose experiment is executing on the bench right now (run_id 0 when none): from its
  // claim until its experiment ends, not while its result is being written (or kept, the store being
  // unavailable). Only these leases are renewed by the host's heartbeat (db::Store::Heartbeat).
  db::Lease executing_lease() const;
  // Calls `write` with the executing lease, if any (else returns Ok without calling it), while the run cannot
  // end: the end of the experiment waits for it. So a progress write never races the run's final write (a
  // progress write after the result is not a stale write: issue 30).
  Status WithExecutingLease(const std::function<Status(const db::Lease&)>& write);

 private:
  void Loop(const std::string& db_path);

  BenchSetup setup_;
  bool keep_traces_ = false;
  mutable std::mutex fault_mu_;
  std::string fault_;
  ClaimPolicy policy_;
  Spool* spool_ = nullptr;
  Registry* registry_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> closing_{false};  // StopCancelling: no more claims, the current run ends as a cancel
  std::function<void(Outcome&)> on_outcome_;
  std::atomic<std::int64_t> current_fence_{0};  // written before current_run_
  std::atomic<std::int64_t> current_run_{0};
  std::atomic<experiment::RunMonitor*> monitor_{nullptr};
  std::mutex monitor_mu_;  // see ExecuteContext::current_monitor_mu
  mutable std::mutex executing_mu_;
  db::Lease executing_;    // executing_lease()
  FaultLog faults_;        // the worker's store faults (claims and its runs' writes), logged once each
};

}  // namespace vb::runs
