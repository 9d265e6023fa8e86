// How request handlers reach running runs without touching the real-time loop (Registry): cancelling sets
// the run's RunMonitor flag (the loop stops within one control period); watchers read the monitor's progress
// atomic and drain the run's LiveTap, a lock-free single-producer ring the loop writes into. Work signalling
// between whoever queues runs and idle workers goes through it too.
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <vector>

#include "experiment/runner.h"
#include "hw/bench.h"

namespace vb::runs {

struct LiveSample {
  double t_s;
  int gate;
  double i_A;
  double x_m;
  double ref;  // the reference of the controlled variable at t_s (NaN when the experiment has none)
  double duty;  // the gate's mean over the interval since the previous live sample (exact where the bench
                // gives its on-time integral, hw::BenchSample::gate_on_s; else the recorded samples' mean)
  std::uint32_t dropped_before;  // live samples lost just before this one (the ring was full)
};

// Every `decimation`-th sample into a fixed ring; the loop never blocks (a full ring drops the sample, and the
// next one that fits says how many were lost before it). `reference` (may be null; must outlive the tap) gives
// each sample its reference value.
class LiveTap final : public hw::SampleSink {
 public:
  explicit LiveTap(int decimation, const experiment::ReferenceProfile* reference = nullptr)
      : reference_(reference), decimation_(decimation > 0 ? decimation : 1) {}
  void OnSample(const hw::BenchSample& s) override;
  // Consumer side; one consumer at a time (the Registry holds its mutex).
  size_t Drain(std::vector<LiveSample>* out);
  // The newest sample's time, stored on every sample (not only the decimated ones): progress by simulated
  // time for a loop that ticks rarely (open-loop PWM has no tick between its segment starts).
  double last_t_s() const { return last_t_s_.load(std::memory_order_relaxed); }

 private:
  static constexpr size_t kCapacity = 8192;
  std::array<LiveSample, kCapacity> ring_{};
  std::atomic<size_t> head_{0}, tail_{0};
  std::atomic<double> last_t_s_{0.0};
  const experiment::ReferenceProfile* reference_;
  int decimation_;
  // Loop-side state (the producer's only): the interval since the previous live sample.
  int count_ = 0;
  double gate_sum_ = 0.0;
  bool have_origin_ = false;
  double origin_t_s_ = 0.0, origin_on_s_ = 0.0;
  std::uint32_t lost_ = 0;
};

// WatchRun's sample_rate_Hz (proto/valvebench/v1/api.proto): keeps at most rate_Hz samples per second of run
// time from the live stream (which the tap already thins to ~1 kHz); rate_Hz <= 0 keeps none. A kept sample
// speaks for the ones thinned out before it: its duty is their mean (each live sample spans the same number of
// recorded samples, so the plain mean is the time mean) and the losses before any of them are summed.
class SampleThinner {
 public:
  explicit SampleThinner(double rate_Hz) : period_s_(rate_Hz > 0 ? 1.0 / rate_Hz : -1.0) {}
  bool Keep(double t_s) {
    double duty = 0.0;
    std::uint64_t lost = 0;
    return Keep(t_s, 0.0, 0, &duty, &lost);
  }
  // Offers a sample with its interval's duty and the samples lost just before it; true when it is kept, then
  // *duty_out and *lost_out cover everything offered since the previous kept sample.
  bool Keep(double t_s, double duty, std::uint64_t lost_before, double* duty_out, std::uint64_t* lost_out) {
    if (period_s_ < 0) return false;
    duty_sum_ += duty;
    ++offered_;
    lost_ += lost_before;
    if (t_s + 1e-12 < next_t_s_) return false;
    // The next kept sample is one period after this one (not after the last due instant: a gap in the stream
    // does not cause a burst afterwards).
    next_t_s_ = t_s + period_s_;
    *duty_out = duty_sum_ / static_cast<double>(offered_);
    *lost_out = lost_;
    duty_sum_ = 0.0;
    offered_ = 0;
    lost_ = 0;
    return true;
  }

 private:
  double period_s_;
  double next_t_s_ = -1e300;
  double duty_sum_ = 0.0;
  std::uint64_t offered_ = 0, lost_ = 0;
};

class Registry {
 public:
  void Add(std::int64_t run_id, experiment::RunMonitor* monitor, LiveTap* tap, double duration_s);
  void Remove(std::int64_t run_id);
  // Removes the run only if `monitor` is the one registered for it: a run re-claimed on this host while an
  // older attempt still ran here (a lab, docs/lab.md) stays visible when the older attempt ends.
  void Remove(std::int64_t run_id, const experiment::RunMonitor* monitor);
  // True if the run is executing here (its loop is told to stop).
  bool Cancel(std::int64_t run_id);
  // Progress 0..1 of a run executing here.
  bool Progress(std::int64_t run_id, double* progress);
  // Live samples with sequence number >= *seq; advances *seq. False if the run is not executing here. A watcher
  // that fell more than the kept backlog behind skips to its start: *missed (may be null) gets how many it lost.
  bool SamplesSince(std::int64_t run_id, std::uint64_t* seq, std::vector<LiveSample>* out,
                    std::uint64_t* missed = nullptr);
  // A run whose experiment ended and whose result waits in this host's spool for the store (runs/spool.h), since
  // when (unix s); 0 when it does not wait. The API shows it ("result waiting for the store since ...").
  void SetResultWaiting(std::int64_t run_id, double since_unix_s);
  void ClearResultWaiting(std::int64_t run_id);
  double ResultWaitingSince(std::int64_t run_id);
  // Work signalling between submit handlers and idle workers.
  void NotifyWork();
  void WaitForWork(int timeout_ms);

 private:
  struct Running {
    experiment::RunMonitor* monitor;
    LiveTap* tap;
    double duration_s;
    std::deque<LiveSample> recent;
    std::uint64_t first_seq = 0;
  };
  std::mutex mu_;
  std::map<std::int64_t, Running> running_;
  std::map<std::int64_t, double> waiting_;
  std::condition_variable work_cv_;
  std::uint64_t work_generation_ = 0;
};

}  // namespace vb::runs
