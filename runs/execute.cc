#include "runs/execute.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <spdlog/spdlog.h>

#include "common/format.h"
#include "db/trace_writer.h"
#include "experiment/spec.h"
#include "hw/safety.h"

namespace vb::runs {

std::vector<db::Metric> RecordedMetrics(const experiment::Metrics& metrics) {
  std::vector<db::Metric> out;
  for (const auto& [name, value] : experiment::MetricList(metrics))
    if (std::isfinite(value)) out.push_back({name, value});
  return out;
}

bool IsStaleWrite(const Status& st) {
  return st.code() == StatusCode::kFailedPrecondition && st.message().rfind("stale write", 0) == 0;
}

namespace {

// The final state a run's summary maps to; the one place that decides it.
db::RunStatus StatusOf(experiment::RunSummary::Termination t) {
  switch (t) {
    case experiment::RunSummary::Termination::kCancelled: return db::RunStatus::kCancelled;
    case experiment::RunSummary::Termination::kFailed: return db::RunStatus::kFailed;
    default: return db::RunStatus::kDone;
  }
}

// The trace's blocks as store chunks, appended with the run's lease while the run executes (on the trace
// stream's thread; the worker's thread does not touch the store until the Runner returns).
class StoreChunks final : public experiment::BlockSink {
 public:
  StoreChunks(db::Store* store, db::Lease lease) : store_(store), lease_(lease) {
    chunk_.channels = experiment::Trace::ChannelNames();
  }
  Status OnBlock(const experiment::Trace& block, std::uint64_t /*first_sample*/) override {
    const std::size_t n = block.size();
    if (n == 0) return Status::Ok();
    chunk_.index = index_++;
    chunk_.t0_s = block.t_s[0];
    chunk_.sample_period_s = block.sample_period_s;
    chunk_.samples = static_cast<std::int32_t>(n);
    chunk_.data.resize(chunk_.channels.size() * n);
    for (std::size_t c = 0; c < chunk_.channels.size(); ++c)
      for (std::size_t k = 0; k < n; ++k) chunk_.data[c * n + k] = block.Value(c, k);
    error_ = store_->AppendTraceChunk(lease_, chunk_);
    return error_;
  }
  // The store's refusal, if it refused a chunk (then the stream stopped and the Runner failed the run).
  const Status& error() const { return error_; }

 private:
  db::Store* store_;
  db::Lease lease_;
  db::TraceChunk chunk_;
  std::int32_t index_ = 0;
  Status error_;
};

// A stale write: stop writing (no retry), log it; the run's state is whoever holds it now.
Outcome Stale(Outcome out, const db::RunRecord& run, const Status& st) {
  spdlog::warn("run {} (fence {}): stopped writing, the run is no longer this attempt's: {}",
               static_cast<long long>(run.id), static_cast<long long>(run.fence), st.message());
  out.stale = true;
  out.recorded = false;
  out.status = db::RunStatus::kRunning;  // as far as this attempt knows; the store has the truth
  return out;
}

}  // namespace

Outcome Execute(db::Store* store, const db::RunRecord& run, const BenchSetup& setup, const ExecuteContext& ctx) {
  Outcome out;
  out.run_id = run.id;
  auto finish = [&](db::RunStatus status, std::string reason, const std::vector<db::Metric>& metrics) {
    out.status = status;
    out.reason = std::move(reason);
    // A run that never started still reads as failed, with the reason, to whoever looks at the summary.
    if (status == db::RunStatus::kFailed && out.summary.termination != experiment::RunSummary::Termination::kFailed &&
        out.summary.samples == 0) {
      out.summary.termination = experiment::RunSummary::Termination::kFailed;
      out.summary.message = out.reason;
    }
    auto st = store->Finish(db::LeaseOf(run), status, out.reason, metrics);
    out.recorded = st.ok();
    if (IsStaleWrite(st)) {
      out.stale = true;
      spdlog::warn("run {} (fence {}): result not recorded, the run is no longer this attempt's: {}",
                   static_cast<long long>(run.id), static_cast<long long>(run.fence), st.message());
    } else if (!st.ok()) {
      spdlog::error("run {}: cannot record the result: {}", static_cast<long long>(run.id), st.message().c_str());
    }
    return std::move(out);
  };
  const bool stopping = ctx.stop != nullptr && ctx.stop->load();

  // 1. The stored spec, with the bench's configured model as the plant.
  auto spec = experiment::ParseSpecJson(run.spec_json);
  if (!spec.ok()) return finish(db::RunStatus::kFailed, "stored spec does not parse: " + spec.status().message(), {});
  if (setup.kind == "emulated" && !setup.plant_from_spec) *spec->mutable_bench()->mutable_model() = setup.model;
  if (setup.paced) spec->set_realtime(true);

  // 2. The experiment and the bench.
  auto e = experiment::BuildExperiment(*spec);
  if (!e.ok()) return finish(db::RunStatus::kFailed, e.status().message(), {});
  auto opened = OpenBench(setup, *e);
  if (!opened.ok())
    return finish(db::RunStatus::kFailed, "bench " + setup.name + ": " + opened.status().message(), {});
  // A trip puts the bench in its safe state and fails the run with the reason, keeping the samples up to it.
  std::unique_ptr<hw::SafetyBench> safety;
  hw::Bench* bench = opened->get();
  if (setup.interlocks) {
    safety = std::make_unique<hw::SafetyBench>(opened->get(), setup.safety);
    bench = safety.get();
  }

  // 3. Run it, visible to watchers.
  experiment::RunMonitor monitor;
  const int decimation = std::max(1, static_cast<int>(std::lround(e->run.sample_rate_Hz / 1000.0)));
  LiveTap tap(decimation, &e->reference);
  if (ctx.registry != nullptr) ctx.registry->Add(run.id, &monitor, &tap, e->duration_s);
  if (ctx.current_monitor != nullptr) ctx.current_monitor->store(&monitor);
  auto cancel_requested = store->CancelRequested(run.id);
  if (stopping || (cancel_requested.ok() && *cancel_requested)) monitor.cancel.store(true);
  bench->set_cancel_flag(&monitor.cancel);  // cancel and shutdown stop a long bench step (hw::Bench)
  StoreChunks chunks(store, db::LeaseOf(run));
  experiment::RunOptions options;
  options.monitor = &monitor;
  options.extra_sink = ctx.registry != nullptr ? &tap : nullptr;
  options.block_sink = &chunks;
  options.block_samples = db::kDefaultChunkSamples;
  options.keep_whole_trace = ctx.keep_trace;
  out.summary = experiment::Runner::Run(*e, *bench, &out.trace, options);
  bench->SafeState();
  if (ctx.current_monitor != nullptr) {
    std::unique_lock<std::mutex> lock;
    if (ctx.current_monitor_mu != nullptr) lock = std::unique_lock<std::mutex>(*ctx.current_monitor_mu);
    ctx.current_monitor->store(nullptr);
  }
  if (ctx.registry != nullptr) ctx.registry->Remove(run.id, &monitor);

  if (ctx.stop != nullptr && ctx.stop->load() &&
      out.summary.termination == experiment::RunSummary::Termination::kCancelled) {
    out.status = db::RunStatus::kRunning;  // left for RecoverAfterCrash on the next start
    return out;
  }

  // 4. Record. A run that stopped early says where it stopped and keeps how far it got (issue 14: cancelled
  // runs read 0 %, and a cancel that cut a long bench step short stated the step's end as the time). Where the
  // bench really got to is the last recorded sample (to one sample period), not the tick the Runner aimed at.
  if (out.summary.termination != experiment::RunSummary::Termination::kDone && out.summary.samples > 0 &&
      out.summary.last_sample_t_s < out.summary.duration_s) {
    out.summary.duration_s = out.summary.last_sample_t_s;
    if (out.summary.termination == experiment::RunSummary::Termination::kCancelled)
      out.summary.message = "cancelled at t = " + FormatNumber(out.summary.duration_s) + " s of " +
                            FormatNumber(e->duration_s) + " s";
  }
  if (out.summary.termination != experiment::RunSummary::Termination::kDone && e->duration_s > 0) {
    const double reached = std::clamp(out.summary.duration_s / e->duration_s, 0.0, 1.0);
    if (auto st = store->SetProgress(db::LeaseOf(run), reached); IsStaleWrite(st)) {
      return Stale(std::move(out), run, st);
    } else if (!st.ok()) {
      spdlog::warn("run {}: cannot record its progress: {}", static_cast<long long>(run.id), st.message().c_str());
    }
  }
  // The trace is in the store already (a chunk the store refused failed the run, "recording: ...").
  if (IsStaleWrite(chunks.error())) return Stale(std::move(out), run, chunks.error());
  db::RunStatus status = StatusOf(out.summary.termination);
  std::string reason = out.summary.message;
  if (status == db::RunStatus::kCancelled) {
    // Keep why it was cancelled (the request's reason, stored by RequestCancel), not only when.
    if (auto row = store->GetRun(run.id); row.ok() && !row->reason.empty()) reason = row->reason + "; " + reason;
  }
  return finish(status, std::move(reason), RecordedMetrics(out.summary.metrics));
}

}  // namespace vb::runs
