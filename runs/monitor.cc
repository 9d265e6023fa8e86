#include "runs/monitor.h"

#include <algorithm>
#include <chrono>
#include <limits>

namespace vb::runs {

void LiveTap::OnSample(const hw::BenchSample& s) {
  last_t_s_.store(s.t_s, std::memory_order_relaxed);
  if (++count_ < decimation_) return;
  count_ = 0;
  const size_t head = head_.load(std::memory_order_relaxed);
  const size_t next = (head + 1) % kCapacity;
  if (next == tail_.load(std::memory_order_acquire)) return;  // full: drop, never block
  // ReferenceProfile::At is arithmetic on the profile's fixed data: no allocation, lock or I/O in the loop.
  const double ref = reference_ != nullptr && reference_->has_reference() ? reference_->At(s.t_s).value
                                                                          : std::numeric_limits<double>::quiet_NaN();
  ring_[head] = LiveSample{s.t_s, s.gate, s.i_A, s.x_m, ref};
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

void Registry::Remove(std::int64_t run_id, const experiment::RunMonitor* monitor) {
  std::lock_guard<std::mutex> lock(mu_);
  if (auto it = running_.find(run_id); it != running_.end() && it->second.monitor == monitor) running_.erase(it);
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
  double t = it->second.monitor->t_s.load(std::memory_order_relaxed);
  if (it->second.tap != nullptr) t = std::max(t, it->second.tap->last_t_s());  // between ticks: the samples
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

void Registry::SetResultWaiting(std::int64_t run_id, double since_unix_s) {
  std::lock_guard<std::mutex> lock(mu_);
  waiting_[run_id] = since_unix_s;
}

void Registry::ClearResultWaiting(std::int64_t run_id) {
  std::lock_guard<std::mutex> lock(mu_);
  waiting_.erase(run_id);
}

double Registry::ResultWaitingSince(std::int64_t run_id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = waiting_.find(run_id);
  return it == waiting_.end() ? 0.0 : it->second;
}

}  // namespace vb::runs
