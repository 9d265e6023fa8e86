#include "server/workers.h"

#include <chrono>
#include <cmath>
#include <cstdio>

#include "db/trace_writer.h"
#include "experiment/spec.h"
#include "hw/emulated_bench.h"
#include "hw/safety.h"
#include "server/benches.h"

namespace vb::server {

void LiveTap::OnSample(const hw::BenchSample& s) {
  if (++count_ < decimation_) return;
  count_ = 0;
  const size_t head = head_.load(std::memory_order_relaxed);
  const size_t next = (head + 1) % kCapacity;
  if (next == tail_.load(std::memory_order_acquire)) return;  // full: drop, never block
  ring_[head] = LiveSample{s.t_s, s.gate, s.i_A, s.x_m};
  head_.store(next, std::memory_order_release);
}

size_t LiveTap::Drain(std::vector<LiveSample>* out) {
  size_t n = 0;
  size_t tail = tail_.load(std::memory_order_relaxed);
  const size_t head = head_.load(std::memory_order_acquire);
  while (tail != head) {
    out->push_back(ring_[tail]);
    tail = (tail + 1) % kCapacity;
    ++n;
  }
  tail_.store(tail, std::memory_order_release);
  return n;
}

void Registry::Add(std::int64_t run_id, experiment::RunMonitor* monitor, LiveTap* tap, double duration_s) {
  std::lock_guard<std::mutex> lock(mu_);
  running_[run_id] = Running{monitor, tap, duration_s, {}, 0};
}

void Registry::Remove(std::int64_t run_id) {
  std::lock_guard<std::mutex> lock(mu_);
  running_.erase(run_id);
}

bool Registry::Cancel(std::int64_t run_id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = running_.find(run_id);
  if (it == running_.end()) return false;
  it->second.monitor->cancel.store(true, std::memory_order_relaxed);
  return true;
}

bool Registry::Progress(std::int64_t run_id, double* progress) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = running_.find(run_id);
  if (it == running_.end()) return false;
  const double t = it->second.monitor->t_s.load(std::memory_order_relaxed);
  *progress = it->second.duration_s > 0.0 ? std::min(1.0, t / it->second.duration_s) : 0.0;
  return true;
}

bool Registry::SamplesSince(std::int64_t run_id, std::uint64_t* seq, std::vector<LiveSample>* out) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = running_.find(run_id);
  if (it == running_.end()) return false;
  Running& r = it->second;
  std::vector<LiveSample> fresh;
  r.tap->Drain(&fresh);
  for (const auto& s : fresh) r.recent.push_back(s);
  constexpr size_t kKeep = 16384;
  while (r.recent.size() > kKeep) {
    r.recent.pop_front();
    ++r.first_seq;
  }
  if (*seq < r.first_seq) *seq = r.first_seq;
  for (std::uint64_t k = *seq - r.first_seq; k < r.recent.size(); ++k) out->push_back(r.recent[k]);
  *seq = r.first_seq + r.recent.size();
  return true;
}

void Registry::NotifyWork() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    ++work_generation_;
  }
  work_cv_.notify_all();
}

void Registry::WaitForWork(int timeout_ms) {
  std::unique_lock<std::mutex> lock(mu_);
  const std::uint64_t gen = work_generation_;
  work_cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [&] { return work_generation_ != gen; });
}

Worker::Worker(BenchSetup setup, std::string db_path, Registry* registry)
    : setup_(std::move(setup)), db_path_(std::move(db_path)), registry_(registry) {}

Worker::~Worker() { Stop(); }

void Worker::Start() { thread_ = std::thread([this] { Loop(); }); }

void Worker::Stop() {
  stop_.store(true);
  if (auto* m = monitor_.load()) m->cancel.store(true);
  registry_->NotifyWork();
  if (thread_.joinable()) thread_.join();
}

void Worker::Loop() {
  auto store = db::Store::Open(db_path_);
  if (!store.ok()) {
    std::fprintf(stderr, "valvebench-server: bench %s: cannot open the store: %s\n", setup_.name.c_str(),
                 store.status().message().c_str());
    return;
  }
  while (!stop_.load()) {
    auto claimed = (*store)->ClaimNext(setup_.bench_class, setup_.name);
    if (!claimed.ok()) {
      std::fprintf(stderr, "valvebench-server: bench %s: claim failed: %s\n", setup_.name.c_str(),
                   claimed.status().message().c_str());
      registry_->WaitForWork(200);
      continue;
    }
    if (!claimed->has_value()) {
      registry_->WaitForWork(200);
      continue;
    }
    Execute(store->get(), **claimed);
  }
}

void Worker::Execute(db::Store* store, const db::RunRecord& run) {
  current_run_.store(run.id);
  auto finish = [&](db::RunStatus status, const std::string& reason, const std::vector<db::Metric>& metrics) {
    auto st = store->Finish(run.id, status, reason, metrics);
    if (!st.ok())
      std::fprintf(stderr, "valvebench-server: run %lld: cannot record the result: %s\n",
                   static_cast<long long>(run.id), st.message().c_str());
  };
  auto spec = experiment::ParseSpecJson(run.spec_json);
  if (!spec.ok()) {
    finish(db::RunStatus::kFailed, "stored spec does not parse: " + spec.status().message(), {});
    current_run_.store(0);
    return;
  }
  // On an emulated bench the bench's configured model is the plant (it stands in for hardware); the spec's
  // perturbations still apply on top of it.
  if (setup_.kind == "emulated") *spec->mutable_bench()->mutable_model() = setup_.model;
  auto e = experiment::BuildExperiment(*spec);
  if (!e.ok()) {
    finish(db::RunStatus::kFailed, e.status().message(), {});
    current_run_.store(0);
    return;
  }
  auto opened = OpenBench(setup_, *e);
  if (!opened.ok()) {
    finish(db::RunStatus::kFailed, "bench " + setup_.name + ": " + opened.status().message(), {});
    current_run_.store(0);
    return;
  }
  // Every run goes through the interlocks (current, duty, on-time, coil temperature, watchdog): a trip puts the
  // bench in its safe state and fails the run with the reason, keeping the samples up to the trip.
  hw::SafetyBench bench(opened->get(), setup_.safety);

  experiment::RunMonitor monitor;
  const int decimation = std::max(1, static_cast<int>(std::lround(e->run.sample_rate_Hz / 1000.0)));
  LiveTap tap(decimation);
  registry_->Add(run.id, &monitor, &tap, e->duration_s);
  monitor_.store(&monitor);
  auto cancel_requested = store->CancelRequested(run.id);
  if (stop_.load() || (cancel_requested.ok() && *cancel_requested)) monitor.cancel.store(true);

  bench.set_cancel_flag(&monitor.cancel);  // cancel and shutdown act within a check period, not a tick
  experiment::Trace trace;
  const experiment::RunSummary summary = experiment::Runner::Run(*e, bench, &trace, &monitor, &tap);
  bench.SafeState();
  monitor_.store(nullptr);
  registry_->Remove(run.id);

  if (stop_.load() && summary.termination == experiment::RunSummary::Termination::kCancelled) {
    // Server shutdown: leave the run marked running; the next start interrupts and re-queues it.
    current_run_.store(0);
    return;
  }
  auto st = db::AppendRecordedTrace(store, run.id, trace);
  std::vector<db::Metric> metrics;
  for (const auto& [name, value] : experiment::MetricList(summary.metrics))
    if (std::isfinite(value)) metrics.push_back({name, value});
  db::RunStatus status = db::RunStatus::kDone;
  std::string reason;
  if (summary.termination == experiment::RunSummary::Termination::kCancelled) {
    status = db::RunStatus::kCancelled;
    reason = summary.message;
    // Keep why it was cancelled (the request's reason, stored by RequestCancel), not only when.
    if (auto row = store->GetRun(run.id); row.ok() && !row->reason.empty()) reason = row->reason + "; " + reason;
  } else if (summary.termination == experiment::RunSummary::Termination::kFailed) {
    status = db::RunStatus::kFailed;
    reason = summary.message;
  } else if (!st.ok()) {
    status = db::RunStatus::kFailed;
    reason = "storing the trace failed: " + st.message();
  }
  finish(status, reason, metrics);
  current_run_.store(0);
}

}  // namespace vb::server
