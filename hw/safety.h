// SafetyBench: the interlocks every bench runs behind, emulated ones included. It wraps any Bench and
//   * trips on coil current (every recorded sample and every measurement), on a PWM duty above the limit, on
//     the gate held high longer than the continuous on-time limit, on the estimated coil temperature, on a
//     measurement that is stale (its time does not reach the tick) or not a number, and on any error of the
//     bench below (device errors);
//   * runs a software watchdog: a thread that puts the bench in its safe state when the control loop has
//     not called into the bench for watchdog_s of wall time (a hung controller or host);
//   * on a trip: the safe state at once (gate low, PWM stopped), and every later call answers Aborted with
//     the reason, so the Runner ends the run as failed with it and keeps the samples up to the trip.
//
// Long AdvanceTo() steps are split into pieces of at most check_period_s, so a trip found in the samples
// stops the coil within that much bench time even when the controller ticks rarely (open-loop runs).
//
// Temperature estimate (a first-order thermal model of the winding): R(T) = R20 (1 + 0.00393 (T - 20 C)),
// P = i^2 R(T), C dT/dt = P - (T - T_ambient) / R_th with C = tau / R_th; integrated exactly over each
// measurement interval with P held.
//
// The loop side takes one uncontended bench-internal mutex per call (never shared with the network); the
// watchdog only try_locks it, so it cannot stall the loop. If the loop is stuck inside the bench below, the
// bench's own timeouts and the device's watchdog act.
#pragma once

#include <atomic>
#include <condition_variable>
#include <limits>
#include <mutex>
#include <string>
#include <thread>

#include "hw/bench.h"

namespace vb::hw {

struct SafetyLimits {
  double max_current_A = 0.0;        // |i| above trips; 0 = the bench's capability max_current_A
  double max_duty = 1.0;             // a PWM command above trips (gate-level commands: see max_on_time_s)
  double max_on_time_s = 0.0;        // gate continuously high (gate 1, or duty 1) longer trips; 0 = no limit
  double max_coil_temp_C = 0.0;      // estimated winding temperature above trips; 0 = no estimate
  double coil_R_ohm = 0.0;           // winding resistance at 20 C (needed with max_coil_temp_C)
  double ambient_C = 25.0;           // also the winding temperature at the run start
  double thermal_resistance_K_per_W = 0.0;  // winding to ambient
  double thermal_time_constant_s = 0.0;     // of the winding
  double watchdog_s = 0.0;           // software watchdog on the control loop (wall time); 0 = off
  double check_period_s = 1e-3;      // longest bench-time step between checks

  // InvalidArgument naming the field.
  Status Validate() const;
};

class SafetyBench final : public Bench {
 public:
  // `inner` must outlive this bench.
  SafetyBench(Bench* inner, SafetyLimits limits);
  ~SafetyBench() override;

  const Capabilities& capabilities() const override { return caps_; }
  Status Configure(const RunConfig& config) override;
  Status Start(SampleSink* sink) override;
  Status Apply(const SwitchCommand& command) override;
  Status AdvanceTo(double t_s, Measurement* m) override;
  Status Stop() override;
  void SafeState() noexcept override;
  LoopStats loop_stats() const override { return inner_->loop_stats(); }

  // The run's cancel flag (a server worker's RunMonitor): a long AdvanceTo() stops at the next check period
  // once it is set and puts the bench in its safe state, so cancel and shutdown (SIGTERM) do not wait for the
  // controller's next tick. Not a trip: AdvanceTo answers Aborted("cancelled ...") and the Runner, seeing the
  // flag, ends the run as cancelled. May be null.
  void set_cancel_flag(const std::atomic<bool>* cancel) override {
    cancel_ = cancel;
    inner_->set_cancel_flag(cancel);
  }

  // The inner bench's exact trajectory passes through untouched (the interlocks act on samples and commands).
  bool set_trajectory_sink(TrajectorySink* sink) override { return inner_->set_trajectory_sink(sink); }

  // A trip was claimed and the inner bench's safe state has been applied (not only claimed: the watchdog thread
  // claims, then drives the bench safe; a caller that sees true may rely on the gate being off).
  bool tripped() const { return safe_after_trip_.load(std::memory_order_acquire); }
  double coil_temp_C() const { return temp_C_; }
  const SafetyLimits& limits() const { return lim_; }

 private:
  class Guard final : public SampleSink {
   public:
    SafetyBench* self = nullptr;
    SampleSink* next = nullptr;
    void OnSample(const BenchSample& s) override;
  };
  Status Trip(std::string reason);           // loop thread
  bool Claim(std::string reason);            // any thread: true if this call set the reason
  Status Tripped() const;
  Status Check(const Measurement& m, double t_s);
  void Beat();
  void WatchdogLoop();
  void StopWatchdog();

  Bench* inner_;
  SafetyLimits lim_;
  Capabilities caps_;
  Guard guard_;
  double max_current_A_ = 0.0;
  bool running_ = false;
  double t_s_ = 0.0;                         // bench time reached
  double temp_C_ = 0.0, last_i_A_ = 0.0;
  bool on_ = false;                          // gate continuously high since on_since_s_
  double on_since_s_ = 0.0;
  double sample_trip_t_s_ = std::numeric_limits<double>::quiet_NaN(), sample_trip_i_A_ = 0.0;

  const std::atomic<bool>* cancel_ = nullptr;
  std::mutex inner_mu_;                      // the loop's calls into inner_ vs the watchdog's SafeState
  std::atomic<bool> claimed_{false};         // the first tripper writes reason_, then sets tripped_
  std::atomic<bool> tripped_{false};
  std::atomic<bool> safe_after_trip_{false};  // set after SafeState() of a trip (tripped())
  std::string reason_;
  std::atomic<std::int64_t> last_beat_ns_{0};
  std::thread watchdog_;
  std::mutex wd_mu_;
  std::condition_variable wd_cv_;
  bool wd_stop_ = false;
};

}  // namespace vb::hw
