#include "experiment/runner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "control/open_loop_pwm.h"
#include "common/format.h"
#include "experiment/trajectory_metrics.h"
#include "model/flow.h"

namespace vb::experiment {

const char* TerminationName(RunSummary::Termination t) {
  switch (t) {
    case RunSummary::Termination::kDone: return "done";
    case RunSummary::Termination::kFailed: return "failed";
    case RunSummary::Termination::kCancelled: return "cancelled";
  }
  return "?";
}

std::string RunSummary::BriefReport() const {
  std::ostringstream os;
  os << TerminationName(termination) << ": " << duration_s << " s, " << samples << " samples, " << ticks
     << " ticks, " << realtime_factor << "x real time";
  if (!message.empty()) os << " (" << message << ")";
  return os.str();
}

std::string RunSummary::FullReport() const {
  std::ostringstream os;
  os << BriefReport() << "\n";
  if (loop.ticks > 0)
    os << "loop: " << loop.ticks << " paced ticks, " << loop.overruns << " overruns, jitter p50 "
       << loop.jitter_p50_s * 1e6 << " us, p99 " << loop.jitter_p99_s * 1e6 << " us, max "
       << loop.jitter_max_s * 1e6 << " us\n";
  for (const auto& w : warnings) os << "warning: " << w << "\n";
  for (const auto& [name, value] : MetricList(metrics))
    if (!std::isnan(value)) os << "  " << name << " = " << value << "\n";
  return os.str();
}

hw::EmulatedBenchOptions EmulatedBenchFor(const Experiment& e) {
  hw::EmulatedBenchOptions opts;
  opts.name = "emulator";
  opts.plant = e.plant;
  opts.driver = e.driver;
  opts.disturbance = e.disturbance;
  return opts;
}

namespace {

// Sends each sample to the recorder and to an optional second sink.
class TeeSink final : public hw::SampleSink {
 public:
  TeeSink(hw::SampleSink* a, hw::SampleSink* b) : a_(a), b_(b) {}
  void OnSample(const hw::BenchSample& s) override {
    a_->OnSample(s);
    if (b_ != nullptr) b_->OnSample(s);
  }

 private:
  hw::SampleSink* a_;
  hw::SampleSink* b_;
};

RunSummary RunImpl(const Experiment& e, hw::Bench& bench, Trace* trace, const std::atomic<bool>* cancel,
                   std::atomic<double>* progress_t, hw::SampleSink* extra_sink, const RunOptions* stream);

// The stream's consumer side: the metrics see every block, then the caller's sink stores it (and the whole
// trace is kept only when asked).
class StreamedRecording final : public BlockSink {
 public:
  StreamedRecording(MetricsAccumulator* metrics, BlockSink* sink, Trace* whole)
      : metrics_(metrics), sink_(sink), whole_(whole) {}
  Status OnBlock(const Trace& block, std::uint64_t first_sample) override {
    metrics_->Add(block);
    if (block.size() > 0) last_t_s_ = block.t_s.back();
    if (whole_ != nullptr) {
      for (size_t k = 0; k < block.size(); ++k) {
        whole_->t_s.push_back(block.t_s[k]);
        whole_->gate.push_back(block.gate[k]);
        whole_->v_coil_V.push_back(block.v_coil_V[k]);
        whole_->i_A.push_back(block.i_A[k]);
        whole_->x_m.push_back(block.x_m[k]);
        whole_->v_mps.push_back(block.v_mps[k]);
        whole_->ref.push_back(block.ref[k]);
        whole_->x_avg_m.push_back(block.x_avg_m[k]);
        whole_->flow_kg_per_s.push_back(block.flow_kg_per_s[k]);
        whole_->v2_int_V2s.push_back(block.v2_int_V2s[k]);
        whole_->energy_int_J.push_back(block.energy_int_J[k]);
        whole_->switch_count.push_back(block.switch_count[k]);
      }
    }
    return sink_->OnBlock(block, first_sample);
  }
  double last_t_s() const { return last_t_s_; }

 private:
  MetricsAccumulator* metrics_;
  BlockSink* sink_;
  Trace* whole_;
  double last_t_s_ = 0.0;
};

}  // namespace

RunSummary Runner::Run(const Experiment& e, hw::Bench& bench, Trace* trace, const std::atomic<bool>* cancel) {
  return RunImpl(e, bench, trace, cancel, nullptr, nullptr, nullptr);
}

RunSummary Runner::Run(const Experiment& e, hw::Bench& bench, Trace* trace, RunMonitor* monitor,
                       hw::SampleSink* extra_sink) {
  return RunImpl(e, bench, trace, monitor ? &monitor->cancel : nullptr, monitor ? &monitor->t_s : nullptr,
                 extra_sink, nullptr);
}

RunSummary Runner::Run(const Experiment& e, hw::Bench& bench, Trace* trace, const RunOptions& options) {
  RunMonitor* monitor = options.monitor;
  return RunImpl(e, bench, trace, monitor ? &monitor->cancel : nullptr, monitor ? &monitor->t_s : nullptr,
                 options.extra_sink, options.block_sink != nullptr ? &options : nullptr);
}

namespace {

RunSummary RunImpl(const Experiment& e, hw::Bench& bench, Trace* trace, const std::atomic<bool>* cancel,
                   std::atomic<double>* progress_t, hw::SampleSink* extra_sink, const RunOptions* stream_options) {
  RunSummary sum;
  const auto wall0 = std::chrono::steady_clock::now();
  trace->Clear();
  const double dt_sample = e.run.sample_rate_Hz > 0.0 ? 1.0 / e.run.sample_rate_Hz : 0.0;
  const double samples = dt_sample > 0.0 ? std::floor(e.duration_s / dt_sample + 1e-9) + 2.0 : 0.0;
  DriverLossInputs driver;
  driver.supply_V = e.run.supply_V;
  driver.diode_drop_V = e.driver.diode_drop_V;
  driver.low_side_flyback = e.driver.kind == model::DriverKind::kLowSideFlyback;
  // Streaming: the metrics see the blocks as they pass; the settling band comes from the reference at the
  // window's last planned sample (MetricsAccumulator).
  const double window_end_s = std::min(e.metric_end_s, e.duration_s);
  double final_ref = std::numeric_limits<double>::quiet_NaN();
  if (e.reference.has_reference() && dt_sample > 0.0)
    final_ref = e.reference.At(std::floor(window_end_s / dt_sample + 1e-9) * dt_sample).value;
  MetricsAccumulator streamed_metrics(e.controlled, e.metric_start_s, window_end_s, e.plant.x_min_m, e.plant.x_max_m,
                                      driver, final_ref);
  std::unique_ptr<StreamedRecording> recording;
  std::unique_ptr<TraceStream> stream;
  try {
    if (stream_options != nullptr) {
      recording = std::make_unique<StreamedRecording>(&streamed_metrics, stream_options->block_sink,
                                                      stream_options->keep_whole_trace ? trace : nullptr);
      stream = std::make_unique<TraceStream>(std::max<size_t>(1, stream_options->block_samples),
                                             stream_options->stream_blocks, dt_sample, recording.get());
      trace->sample_period_s = dt_sample;
    } else {
      trace->Reserve(static_cast<size_t>(samples));
    }
  } catch (const std::exception&) {
    // Admission budgets traces (runs/admit.h); a memory cap it cannot see (a cgroup) still must not end the
    // process: the run fails with the reason, before the bench is touched.
    trace->Clear();
    sum.termination = RunSummary::Termination::kFailed;
    sum.message = "recording: cannot reserve memory for " + std::to_string(static_cast<long long>(samples)) +
                  " samples (" + std::to_string(static_cast<long long>(samples * Trace::kBytesPerSample / 1e6)) +
                  " MB); lower recording.rate_Hz or duration_s";
    return sum;
  }
  Recorder recorder(stream ? stream->first() : trace, &e.reference, &e.plant, e.run.supply_pressure_Pa, dt_sample,
                    e.average_window_s);
  if (stream) recorder.StreamTo(stream.get());

  auto fail = [&](const Status& st, RunSummary::Termination term) {
    bench.SafeState();
    (void)bench.Stop();
    sum.termination = term;
    sum.message = st.message();
  };

  // The exact trajectory, where the bench has one: the metrics that integrate or extremise over time come from
  // it, not from the recording (docs/metrics.md). The settling band is the reference just before the window's end.
  const double exact_final_ref =
      e.reference.has_reference() ? e.reference.At(std::nextafter(window_end_s, 0.0)).value
                                  : std::numeric_limits<double>::quiet_NaN();
  TrajectoryMetrics exact(e.controlled, &e.reference, e.metric_start_s, window_end_s, exact_final_ref,
                          model::MassFlow_kg_per_s(e.plant, 1.0, e.run.supply_pressure_Pa));
  sum.metrics_from_trajectory = bench.set_trajectory_sink(&exact);
  struct DetachTrajectory {
    hw::Bench* bench;
    bool attached;
    ~DetachTrajectory() {
      if (attached) bench->set_trajectory_sink(nullptr);
    }
  } detach{&bench, sum.metrics_from_trajectory};

  TeeSink tee(&recorder, extra_sink);
  Status st = bench.Configure(e.run);
  if (st.ok()) st = bench.Start(&tee);
  if (!st.ok()) {
    fail(st, RunSummary::Termination::kFailed);
    return sum;
  }

  const control::Controller& ctl = *e.controller;
  control::ControllerState state = ctl.InitialState();
  // A paced run ticks at least every kMaxPacedTick_s, so that open-loop runs exercise (and report) the loop.
  constexpr double kMaxPacedTick_s = 1e-3;
  const double period = e.run.realtime ? std::min(ctl.period_s(), kMaxPacedTick_s) : ctl.period_s();
  const std::vector<double>& bp = e.breakpoints_s;
  size_t next_bp = 0;
  std::int64_t next_ctl = 1;  // the next controller instant is next_ctl * period
  double t = 0.0;
  Measurement m;
  bool cancelled = false;
  // Seed 002's ||u||_2 over the metric window: the law's input u held from one tick to the next (plain
  // doubles: the loop stays allocation-free).
  const int u_slot = ctl.input_slot();
  const double w0 = e.metric_start_s, w1 = std::min(e.metric_end_s, e.duration_s);
  double u_held = std::numeric_limits<double>::quiet_NaN(), u_since = 0.0, u2_int = 0.0;
  auto accumulate_u = [&](double until) {
    const double a = std::max(u_since, w0), b = std::min(until, w1);
    if (b > a && std::isfinite(u_held)) u2_int += u_held * u_held * (b - a);
  };
  while (t < e.duration_s) {
    st = bench.AdvanceTo(t, &m);
    // A bench may cut a long step short when the run is cancelled (SafetyBench does): that is a cancellation.
    if (cancel != nullptr && cancel->load(std::memory_order_relaxed)) {
      cancelled = true;
      break;
    }
    if (!st.ok()) break;
    if (stream && stream->failed()) break;  // the recording cannot go on: Close() says why
    const SwitchCommand cmd = ctl.Step(m, e.reference.At(t), &state);
    if (cmd.mode == SwitchCommand::Mode::kPwm) sum.max_carrier_Hz = std::max(sum.max_carrier_Hz, cmd.carrier_Hz);
    st = bench.Apply(cmd);
    if (!st.ok()) break;
    if (u_slot >= 0) {
      accumulate_u(t);
      u_held = state.x[static_cast<size_t>(u_slot)];
      u_since = t;
    }
    ++sum.ticks;
    if (progress_t != nullptr) progress_t->store(t, std::memory_order_relaxed);
    // Next tick: the earliest controller instant or breakpoint after t.
    while (next_bp < bp.size() && bp[next_bp] <= t + 1e-12) ++next_bp;
    while (static_cast<double>(next_ctl) * period <= t + 1e-12) ++next_ctl;
    double t_next = std::min(static_cast<double>(next_ctl) * period, e.duration_s);
    if (next_bp < bp.size()) t_next = std::min(t_next, bp[next_bp]);
    t = t_next;
  }
  if (st.ok() && !cancelled && !(stream && stream->failed())) {
    st = bench.AdvanceTo(e.duration_s, &m);
    if (cancel != nullptr && cancel->load(std::memory_order_relaxed)) cancelled = true;
  }
  if (!st.ok() && !cancelled) {
    fail(st, RunSummary::Termination::kFailed);
  } else if (cancelled) {
    fail(Status::Aborted("cancelled at t = " + std::to_string(t) + " s"), RunSummary::Termination::kCancelled);
  } else {
    st = bench.Stop();
    if (!st.ok()) fail(st, RunSummary::Termination::kFailed);
  }
  // The bench is stopped: its last samples are in the last block; the store takes the rest.
  if (stream) {
    const Status recorded = stream->Close(recorder.current());
    sum.record_waits = stream->loop_waits();
    if (!recorded.ok()) {
      bench.SafeState();
      if (sum.termination != RunSummary::Termination::kCancelled) {
        sum.termination = RunSummary::Termination::kFailed;
        sum.message = recorded.WithContext("recording").message();
      }
    }
  }
  sum.duration_s = sum.termination == RunSummary::Termination::kDone ? e.duration_s : t;
  sum.samples = stream ? static_cast<size_t>(stream->samples_handed()) : trace->size();
  sum.last_sample_t_s = stream ? recording->last_t_s() : (trace->size() > 0 ? trace->t_s.back() : 0.0);
  sum.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  sum.realtime_factor = sum.wall_s > 0.0 ? sum.duration_s / sum.wall_s : 0.0;
  sum.loop = bench.loop_stats();
  const double metric_end_s = std::min(e.metric_end_s, sum.duration_s);
  sum.metrics = stream ? streamed_metrics.Finish()
                       : ComputeMetrics(*trace, e.controlled, e.metric_start_s, metric_end_s, e.plant.x_min_m,
                                        e.plant.x_max_m, driver);
  if (sum.metrics_from_trajectory) {
    exact.ApplyTo(&sum.metrics, e.plant.x_max_m, driver);
  }
  // The recording's rate against the fastest switching in the run: the carrier the law commanded, or for a law
  // that switches the gate itself, half its measured switching rate (two edges per period). Below twice it
  // (Nyquist) the trace aliases the ripple: on the emulator the metrics do not use the trace, so it is a note
  // about the view; on hardware the metrics are the samples', so it is a warning about the numbers.
  {
    const double f_switch = std::max(sum.max_carrier_Hz, std::isfinite(sum.metrics.switching_rate_Hz)
                                                             ? 0.5 * sum.metrics.switching_rate_Hz
                                                             : 0.0);
    if (f_switch > 0.0 && e.run.sample_rate_Hz > 0.0 && e.run.sample_rate_Hz < 2.0 * f_switch) {
      const std::string rates = "recording.rate_Hz " + FormatNumber(e.run.sample_rate_Hz) +
                                " Hz is below twice the " + FormatNumber(f_switch) + " Hz switching";
      sum.warnings.push_back(
          sum.metrics_from_trajectory
              ? rates + ": the recorded trace aliases the ripple (a view only: the metrics are from the "
                        "emulator's exact trajectory)"
              : rates + ": tracking metrics, ripple and means come from these samples and alias the ripple; "
                        "record at >= " + FormatNumber(2.0 * f_switch) + " Hz");
    }
  }
  if (u_slot >= 0 && sum.termination == RunSummary::Termination::kDone) {
    accumulate_u(sum.duration_s);
    sum.metrics.effort_u_l2 = std::sqrt(u2_int);
  }
  // The carrier and duty an open-loop law commands at the window start (seed 003's planned f and D).
  if (const auto* pwm = dynamic_cast<const control::OpenLoopPwm*>(&ctl)) {
    for (const auto& seg : pwm->segments()) {
      if (seg.start_s > e.metric_start_s + 1e-12) break;
      sum.metrics.pwm_frequency_Hz = seg.frequency_Hz;
      sum.metrics.pwm_duty = seg.duty;
    }
  }
  if (progress_t != nullptr) progress_t->store(sum.duration_s, std::memory_order_relaxed);
  return sum;
}

}  // namespace

}  // namespace vb::experiment
