#include "runs/monitor.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

namespace vb::runs {

void LiveTap::OnSample(const hw::BenchSample& s) {
  last_t_s_.store(s.t_s, std::memory_order_relaxed);
  if (!have_origin_) {  // the stream's first interval starts at its first sample
    have_origin_ = true;
    origin_t_s_ = s.t_s;
    origin_on_s_ = s.gate_on_s;
  }
  gate_sum_ += s.gate != 0 ? 1.0 : 0.0;
  if (++count_ < decimation_) return;
  // The gate's duty over (previous live sample, this one]: from the bench's exact on-time integral where it has
  // one (a 20 kHz PWM recorded at 50 kHz aliases in the samples' mean: 0.2 or 0.4 for a duty of 0.3), else
  // that mean.
  const double span_s = s.t_s - origin_t_s_;
  double duty = gate_sum_ / count_;
  if (std::isfinite(s.gate_on_s) && std::isfinite(origin_on_s_) && span_s > 0.0)
    duty = std::clamp((s.gate_on_s - origin_on_s_) / span_s, 0.0, 1.0);
  count_ = 0;
  gate_sum_ = 0.0;
  origin_t_s_ = s.t_s;
  origin_on_s_ = s.gate_on_s;
  const size_t head = head_.load(std::memory_order_relaxed);
  const size_t next = (head + 1) % kCapacity;
  if (next == tail_.load(std::memory_order_acquire)) {  // full: drop, never block; the next one says so
    if (lost_ < std::numeric_limits<std::uint32_t>::max()) ++lost_;
    return;
  }
  // ReferenceProfile::At is arithmetic on the profile's fixed data: no allocation, lock or I/O in the loop.
  const double ref = reference_ != nullptr && reference_->has_reference() ? reference_->At(s.t_s).value
                                                                          : std::numeric_limits<double>::quiet_NaN();
  ring_[head] = LiveSample{s.t_s, s.gate, s.i_A, s.x_m, ref, duty, lost_};
  lost_ = 0;
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

bool Registry::SamplesSince(std::int64_t run_id, std::uint64_t* seq, std::vector<LiveSample>* out,
                            std::uint64_t* missed) {
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
  if (*seq < r.first_seq) {
    if (missed != nullptr) *missed += r.first_seq - *seq;
    *seq = r.first_seq;
  }
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
