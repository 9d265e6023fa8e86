#include "experiment/runner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

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
                   std::atomic<double>* progress_t, hw::SampleSink* extra_sink);

}  // namespace

RunSummary Runner::Run(const Experiment& e, hw::Bench& bench, Trace* trace, const std::atomic<bool>* cancel) {
  return RunImpl(e, bench, trace, cancel, nullptr, nullptr);
}

RunSummary Runner::Run(const Experiment& e, hw::Bench& bench, Trace* trace, RunMonitor* monitor,
                       hw::SampleSink* extra_sink) {
  return RunImpl(e, bench, trace, monitor ? &monitor->cancel : nullptr, monitor ? &monitor->t_s : nullptr,
                 extra_sink);
}

namespace {

RunSummary RunImpl(const Experiment& e, hw::Bench& bench, Trace* trace, const std::atomic<bool>* cancel,
                   std::atomic<double>* progress_t, hw::SampleSink* extra_sink) {
  RunSummary sum;
  const auto wall0 = std::chrono::steady_clock::now();
  trace->Clear();
  const double dt_sample = e.run.sample_rate_Hz > 0.0 ? 1.0 / e.run.sample_rate_Hz : 0.0;
  const double samples = dt_sample > 0.0 ? std::floor(e.duration_s / dt_sample + 1e-9) + 2.0 : 0.0;
  try {
    trace->Reserve(static_cast<size_t>(samples));
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
  Recorder recorder(trace, &e.reference, &e.plant, e.run.supply_pressure_Pa, dt_sample, e.average_window_s);

  auto fail = [&](const Status& st, RunSummary::Termination term) {
    bench.SafeState();
    (void)bench.Stop();
    sum.termination = term;
    sum.message = st.message();
  };

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
  while (t < e.duration_s) {
    st = bench.AdvanceTo(t, &m);
    // A bench may cut a long step short when the run is cancelled (SafetyBench does): that is a cancellation.
    if (cancel != nullptr && cancel->load(std::memory_order_relaxed)) {
      cancelled = true;
      break;
    }
    if (!st.ok()) break;
    st = bench.Apply(ctl.Step(m, e.reference.At(t), &state));
    if (!st.ok()) break;
    ++sum.ticks;
    if (progress_t != nullptr) progress_t->store(t, std::memory_order_relaxed);
    // Next tick: the earliest controller instant or breakpoint after t.
    while (next_bp < bp.size() && bp[next_bp] <= t + 1e-12) ++next_bp;
    while (static_cast<double>(next_ctl) * period <= t + 1e-12) ++next_ctl;
    double t_next = std::min(static_cast<double>(next_ctl) * period, e.duration_s);
    if (next_bp < bp.size()) t_next = std::min(t_next, bp[next_bp]);
    t = t_next;
  }
  if (st.ok() && !cancelled) {
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
  sum.duration_s = sum.termination == RunSummary::Termination::kDone ? e.duration_s : t;
  sum.samples = trace->size();
  sum.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  sum.realtime_factor = sum.wall_s > 0.0 ? sum.duration_s / sum.wall_s : 0.0;
  sum.loop = bench.loop_stats();
  sum.metrics = ComputeMetrics(*trace, e.controlled, e.metric_start_s, std::min(e.metric_end_s, sum.duration_s),
                               e.plant.x_min_m, e.plant.x_max_m);
  if (progress_t != nullptr) progress_t->store(sum.duration_s, std::memory_order_relaxed);
  return sum;
}

}  // namespace

}  // namespace vb::experiment
