#include "runs/worker.h"

#include <cstdio>

#include <spdlog/spdlog.h>

#include "db/open_store.h"
#include "runs/build_identity.h"

namespace vb::runs {

Worker::Worker(BenchSetup setup, Registry* registry)
    : setup_(std::move(setup)), registry_(registry), faults_("bench " + setup_.name) {
  ThisBuild();  // the executable's digest read once now, not when the first run finishes (build_identity.h)
}

Worker::~Worker() { Stop(); }

StatusOr<std::optional<Outcome>> Worker::ClaimAndExecute(db::Store* store) {
  db::ClaimRequest request = db::BenchClaim(setup_.bench_class, setup_.name);
  request.host = policy_.host;
  request.lease_ttl_s = policy_.lease_ttl_s;
  request.aging_s = policy_.aging_s;
  auto claimed = store->ClaimNext(request);
  if (!claimed.ok()) return claimed.status();
  if (!claimed->has_value()) return std::optional<Outcome>();
  faults_.Recovered();
  current_fence_.store((*claimed)->fence);
  current_run_.store((*claimed)->id);
  {
    std::lock_guard<std::mutex> lock(executing_mu_);
    executing_ = db::LeaseOf(**claimed);
  }
  ExecuteContext ctx;
  ctx.ended = [this] {
    std::lock_guard<std::mutex> lock(executing_mu_);
    executing_ = db::Lease{};
  };
  ctx.retry.give_up_s = policy_.hold_result_s;
  ctx.faults = &faults_;
  ctx.spool = spool_;
  ctx.registry = registry_;
  ctx.stop = &stop_;
  ctx.current_monitor = &monitor_;
  ctx.keep_trace = keep_traces_;
  ctx.current_monitor_mu = &monitor_mu_;
  Outcome out = Execute(store, **claimed, setup_, ctx);
  {
    std::lock_guard<std::mutex> lock(executing_mu_);
    executing_ = db::Lease{};
  }
  current_run_.store(0);
  {
    // A failure at the bench (not opened, an interlock tripped) marks it faulted until a run ends well again.
    std::lock_guard<std::mutex> lock(fault_mu_);
    if (out.status == db::RunStatus::kDone) {
      fault_.clear();
    } else if (out.bench_fault && (out.status == db::RunStatus::kFailed || out.spooled)) {
      fault_ = out.reason;
    }
  }
  return std::optional<Outcome>(std::move(out));
}

db::Lease Worker::executing_lease() const {
  std::lock_guard<std::mutex> lock(executing_mu_);
  return executing_;
}

Status Worker::WithExecutingLease(const std::function<Status(const db::Lease&)>& write) {
  std::lock_guard<std::mutex> lock(executing_mu_);
  if (executing_.run_id == 0) return Status::Ok();
  return write(executing_);
}

std::string Worker::fault() const {
  std::lock_guard<std::mutex> lock(fault_mu_);
  return fault_;
}

bool Worker::CancelIfCurrent(const db::Lease& lease) {
  if (lease.run_id == 0 || current_run_.load() != lease.run_id || current_fence_.load() != lease.fence) return false;
  std::lock_guard<std::mutex> lock(monitor_mu_);
  experiment::RunMonitor* m = monitor_.load();
  // Re-checked under the lock: the run may have ended (and the worker taken the next) since the check above.
  if (m == nullptr || current_run_.load() != lease.run_id || current_fence_.load() != lease.fence) return false;
  m->cancel.store(true);
  return true;
}

void Worker::Start(std::string db_path) {
  thread_ = std::thread([this, path = std::move(db_path)] { Loop(path); });
}

void Worker::Stop() {
  stop_.store(true);
  {
    std::lock_guard<std::mutex> lock(monitor_mu_);
    if (auto* m = monitor_.load()) m->cancel.store(true);
  }
  if (registry_ != nullptr) registry_->NotifyWork();
  if (thread_.joinable()) thread_.join();
}

void Worker::StopCancelling() {
  closing_.store(true);
  {
    std::lock_guard<std::mutex> lock(monitor_mu_);
    if (auto* m = monitor_.load()) m->cancel.store(true);
  }
  if (registry_ != nullptr) registry_->NotifyWork();
  if (thread_.joinable()) thread_.join();
}

void Worker::Loop(const std::string& db_path) {
  // The store may be unavailable at start or at any time: opening and claiming are retried (every 0.2 s, or
  // when work is signalled), the fault logged once when it begins and once when it ends.
  std::unique_ptr<db::Store> store;
  while (!stop_.load() && !closing_.load()) {
    if (store == nullptr) {
      const auto call_began = FaultLog::Clock::now();
      auto opened = db::OpenStore(db_path);
      if (opened.ok()) {
        store = std::move(opened).value();
      } else if (db::ClassifyWrite(opened.status()) == db::WriteFault::kTransient) {
        faults_.Failed(opened.status(), call_began);
      } else {
        spdlog::error("bench {}: cannot open the store: {}", setup_.name, opened.status().message());
      }
      if (store == nullptr) {
        if (registry_ != nullptr) registry_->WaitForWork(200);
        continue;
      }
    }
    const auto call_began = FaultLog::Clock::now();
    auto done = ClaimAndExecute(store.get());
    if (!done.ok()) {
      if (db::ClassifyWrite(done.status()) == db::WriteFault::kTransient) {
        faults_.Failed(done.status(), call_began);
      } else {
        spdlog::error("bench {}: claim failed: {}", setup_.name, done.status().message());
      }
    } else if (!done->has_value()) {
      faults_.Recovered();
    } else if (on_outcome_) {
      on_outcome_(**done);
    }
    if (!done.ok() || !done->has_value()) registry_->WaitForWork(200);
  }
}

}  // namespace vb::runs
