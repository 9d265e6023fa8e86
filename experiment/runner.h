// The Runner closes the loop on any Bench: every tick it reads the measurement, calls the controller with
// the reference, and applies the command: read -> update -> write (ros2_control). Ticks are at k * the
// controller's period plus the experiment's breakpoints (segment starts, valve command edges, reference
// steps), so nothing the spec schedules is rounded to the control grid.
//
// The loop itself does no allocation, locking or I/O beyond the bench: the trace is reserved beforehand.
#pragma once

#include <atomic>
#include <string>
#include <vector>

#include "experiment/metrics.h"
#include "experiment/spec.h"
#include "experiment/trace.h"
#include "experiment/trace_stream.h"
#include "hw/bench.h"
#include "hw/emulated_bench.h"

namespace vb::experiment {

struct RunSummary {
  enum class Termination { kDone, kFailed, kCancelled };
  Termination termination = Termination::kDone;
  std::string message;              // why it failed or was cancelled
  double duration_s = 0.0;          // simulated / experiment time covered
  size_t samples = 0;
  double wall_s = 0.0;
  double last_sample_t_s = 0.0;     // the last recorded sample's time (where the bench really got to)
  std::uint64_t record_waits = 0;   // streaming: times the loop waited for the store to take a block
  double realtime_factor = 0.0;     // experiment seconds per wall second
  std::uint64_t ticks = 0;
  hw::LoopStats loop;               // pacing (realtime runs)
  Metrics metrics;
  // The metrics' source (docs/metrics.md, "Metrics from the run, not from its recording"): true when the bench
  // handed over its exact trajectory (the emulator), false when they come from the recorded samples (hardware).
  bool metrics_from_trajectory = false;
  double max_carrier_Hz = 0.0;      // the fastest PWM carrier the law commanded (0: gate commands only)
  // What the reader of the numbers must know (a recording below twice the carrier, ...), one sentence each.
  std::vector<std::string> warnings;

  bool ok() const { return termination == Termination::kDone; }
  std::string BriefReport() const;
  std::string FullReport() const;
};
const char* TerminationName(RunSummary::Termination t);

// The emulated bench an experiment asks for: its plant, driver and disturbances. The one place that maps an
// Experiment onto EmulatedBenchOptions, so no caller can forget a field.
hw::EmulatedBenchOptions EmulatedBenchFor(const Experiment& e);

// Lock-free window into a running experiment for another thread (a server worker's monitor): the loop only
// stores relaxed atomics, never waits.
struct RunMonitor {
  std::atomic<bool> cancel{false};   // set by the observer; the loop stops at its next tick
  std::atomic<double> t_s{0.0};      // experiment time reached, updated every tick
};

// How a run records (Runner::Run with options).
struct RunOptions {
  RunMonitor* monitor = nullptr;          // cancel and progress for another thread
  hw::SampleSink* extra_sink = nullptr;   // also receives every sample (a live tap); must not block
  // Streaming (docs/store.md, "Traces while the run executes"): the trace goes to this sink in blocks of
  // block_samples while the run executes, and the run's memory stays `stream_blocks` blocks whatever its
  // length. Metrics are computed on the blocks as they pass. Without a sink the whole trace is reserved up front.
  BlockSink* block_sink = nullptr;
  std::size_t block_samples = 16384;
  int stream_blocks = 4;
  bool keep_whole_trace = false;          // with a sink: also keep every sample in *trace (costs memory)
};

class Runner {
 public:
  // cancel may be null. The trace is cleared and filled. `extra_sink`, if given, also receives every sample
  // (e.g. a live tap); it must not block.
  static RunSummary Run(const Experiment& experiment, hw::Bench& bench, Trace* trace,
                        const std::atomic<bool>* cancel = nullptr);
  static RunSummary Run(const Experiment& experiment, hw::Bench& bench, Trace* trace, RunMonitor* monitor,
                        hw::SampleSink* extra_sink);
  // With a block_sink, *trace ends up with the whole trace only if keep_whole_trace; otherwise it is left
  // empty, and RunSummary::samples and last_sample_t_s say what was recorded.
  static RunSummary Run(const Experiment& experiment, hw::Bench& bench, Trace* trace, const RunOptions& options);
};

}  // namespace vb::experiment
