// The Bench interface: real and emulated hardware behind one contract (after ros2_control).
//
// Lifecycle: Configure(run) -> Start(sink) -> { AdvanceTo(t) -> Apply(cmd) }* -> Stop(). SafeState() may be
// called at any time from the owning thread and always leaves the coil de-energised (gate low, PWM stopped).
// A Bench is not copyable: it stands for one piece of hardware.
//
// Time: t_s is run time from Start(). AdvanceTo(t) returns the measurement at t: an emulated bench integrates
// to t (as fast as possible, or paced to the wall clock); a hardware bench waits for t and reads its inputs.
// Samples at the recording rate go to the SampleSink as they are produced; the sink must not block.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "common/bench_io.h"
#include "common/status.h"

namespace vb::hw {

struct Capabilities {
  std::string kind;                  // "emulated", "hid", "u3"
  std::string driver;                // low_side_flyback | h_bridge | internal_electronics
  double max_supply_V = 0.0;
  double min_carrier_Hz = 0.0;       // PWM carrier range
  double max_carrier_Hz = 0.0;
  double max_sample_rate_Hz = 0.0;   // recording
  double max_control_rate_Hz = 0.0;  // host control loop
  bool measures_position = false;
  bool measures_velocity = false;
  double max_current_A = 0.0;        // safety limit the bench enforces
  // Hardware benches: what identifies the device, and the current loops its firmware runs on-device
  // ("open_loop", "hysteresis", "pi") at up to max_device_loop_Hz.
  std::string serial;
  std::vector<std::string> device_loops;
  double max_device_loop_Hz = 0.0;
};

struct RunConfig {
  double supply_V = 24.0;
  double supply_pressure_Pa = 0.0;   // gauge
  double sample_rate_Hz = 50'000.0;  // recording rate; 0 = no samples
  bool realtime = false;             // pace AdvanceTo to the wall clock
};

// One recorded sample. Channels a bench does not measure are NaN.
struct BenchSample {
  double t_s;
  std::int8_t gate;
  double v_coil_V;
  double i_A;
  double x_m;
  double v_mps;
  // Running integrals from the run start, computed exactly by the bench where it can (NaN otherwise):
  // metrics then do not depend on whether the sample rate resolves the PWM.
  double v2_integral_V2s;   // integral of v_coil^2 dt
  double energy_J;          // integral of v_coil i dt
  double switches;          // gate transitions so far
  double gate_on_s;         // integral of the gate dt: its on-time so far (the live stream's duty)
};

class SampleSink {
 public:
  virtual ~SampleSink() = default;
  virtual void OnSample(const BenchSample& sample) = 0;
};

// The bench's exact trajectory, piece by piece (the emulator's event-exact pieces: docs/metrics.md, "Metrics
// from the run, not from its recording"). A piece is smooth on [t0_s, t1_s]; At() is valid only during the
// OnPiece call. Pieces arrive in time order and cover the run without gaps.
class TrajectoryPiece {
 public:
  virtual ~TrajectoryPiece() = default;
  virtual void At(double t_s, double* i_A, double* x_m) const = 0;  // x_m NaN without a position
};
class TrajectorySink {
 public:
  virtual ~TrajectorySink() = default;
  virtual void OnPiece(double t0_s, double t1_s, const TrajectoryPiece& piece) = 0;
};

// How well a paced loop kept its deadlines.
struct LoopStats {
  std::uint64_t ticks = 0;
  std::uint64_t overruns = 0;        // ticks whose work ended after their deadline
  double jitter_p50_s = 0.0;         // wake-up lateness after the deadline
  double jitter_p99_s = 0.0;
  double jitter_max_s = 0.0;
};

class Bench {
 public:
  Bench() = default;
  Bench(const Bench&) = delete;
  Bench& operator=(const Bench&) = delete;
  virtual ~Bench() = default;

  virtual const Capabilities& capabilities() const = 0;
  virtual Status Configure(const RunConfig& config) = 0;
  // Starts a run from rest at t = 0.
  virtual Status Start(SampleSink* sink) = 0;
  // Takes effect now. FailedPrecondition if the bench cannot realise it (gate -1 without an H-bridge, ...).
  virtual Status Apply(const SwitchCommand& command) = 0;
  // Runs until t_s (>= the current time) and fills *m with the measurement at t_s.
  virtual Status AdvanceTo(double t_s, Measurement* m) = 0;
  // Ends the run: emits the last sample and leaves the bench in its safe state.
  virtual Status Stop() = 0;
  // Gate low, PWM stopped. Safe to call at any time, repeatedly.
  virtual void SafeState() noexcept = 0;
  // Pacing statistics of the last run (zeros when not paced).
  virtual LoopStats loop_stats() const = 0;
  // The run's cancel flag (may be null). A bench that can take long steps (a PWM segment of minutes on the
  // emulator, a bench behind the interlocks) stops a step soon after the flag is set: AdvanceTo then answers
  // Aborted("cancelled at t = ... s") and the Runner, seeing the flag, ends the run as cancelled. Benches whose
  // steps are short anyway need not do anything.
  virtual void set_cancel_flag(const std::atomic<bool>* /*cancel*/) {}
  // Hands the run's exact trajectory to `sink` (null: stop) from the next Start(). False when the bench has no
  // exact trajectory (hardware: its metrics come from its samples).
  virtual bool set_trajectory_sink(TrajectorySink* /*sink*/) { return false; }
};

}  // namespace vb::hw
