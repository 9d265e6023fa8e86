// FaultyBench: injects faults into any bench (after LevelDB's fault-injecting Env), for tests of the safety
// paths: a device error, a stall (the call hangs in wall time), stale or NaN measurements, a current sensor
// that reads high, and a command the bench rejects. Times are bench time from Start(); -1 = never.
#pragma once

#include <string>

#include "hw/bench.h"

namespace vb::hw {

struct BenchFaults {
  double error_at_s = -1.0;          // AdvanceTo(t >= this) fails with `error`
  Status error = Status::Unavailable("injected device error");
  double stall_at_s = -1.0;          // the first AdvanceTo(t >= this) sleeps stall_wall_s of wall time
  double stall_wall_s = 0.0;
  double stale_from_s = -1.0;        // measurements stop updating: the last fresh one is returned again
  double nan_at_s = -1.0;            // the current measurement is NaN
  double current_offset_from_s = -1.0;  // the current reads current_offset_A high (samples and measurements)
  double current_offset_A = 0.0;
  double apply_error_at_s = -1.0;    // Apply() fails with `error`
};

class FaultyBench final : public Bench {
 public:
  // `inner` must outlive this bench.
  FaultyBench(Bench* inner, BenchFaults faults) : inner_(inner), f_(std::move(faults)) {}

  const Capabilities& capabilities() const override { return inner_->capabilities(); }
  Status Configure(const RunConfig& config) override { return inner_->Configure(config); }
  Status Start(SampleSink* sink) override;
  Status Apply(const SwitchCommand& command) override;
  Status AdvanceTo(double t_s, Measurement* m) override;
  Status Stop() override { return inner_->Stop(); }
  void SafeState() noexcept override {
    ++safe_state_calls_;
    inner_->SafeState();
  }
  LoopStats loop_stats() const override { return inner_->loop_stats(); }

  int safe_state_calls() const { return safe_state_calls_; }

 private:
  class Offset final : public SampleSink {
   public:
    FaultyBench* self = nullptr;
    SampleSink* next = nullptr;
    void OnSample(const BenchSample& s) override;
  };
  static bool Due(double at_s, double t_s) { return at_s >= 0.0 && t_s >= at_s - 1e-12; }

  Bench* inner_;
  BenchFaults f_;
  Offset offset_;
  double t_s_ = 0.0;
  bool stalled_ = false;
  Measurement last_fresh_;
  int safe_state_calls_ = 0;
};

}  // namespace vb::hw
