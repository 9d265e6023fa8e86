#include "runs/execute.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>

#include <spdlog/spdlog.h>

#include "common/format.h"
#include "db/text.h"
#include "db/trace_writer.h"
#include "experiment/spec.h"
#include "hw/safety.h"
#include "runs/build_identity.h"

namespace vb::runs {

std::vector<db::Metric> RecordedMetrics(const experiment::Metrics& metrics) {
  std::vector<db::Metric> out;
  for (const auto& [name, value] : experiment::MetricList(metrics))
    if (std::isfinite(value)) out.push_back({name, value});
  return out;
}

db::ExecutionRecord RecordedExecution(const experiment::RunSummary& summary) {
  db::ExecutionRecord e;
  e.wall_s = summary.wall_s;
  e.simulated_s = summary.duration_s;
  e.samples = static_cast<std::int64_t>(summary.samples);
  e.control_ticks = static_cast<std::int64_t>(summary.ticks);
  e.metrics_from_trajectory = summary.metrics_from_trajectory;
  e.build = ThisBuild();
  if (summary.loop.ticks > 0) {
    db::LoopRecord l;
    l.ticks = static_cast<std::int64_t>(summary.loop.ticks);
    l.overruns = static_cast<std::int64_t>(summary.loop.overruns);
    l.jitter_p50_s = summary.loop.jitter_p50_s;
    l.jitter_p99_s = summary.loop.jitter_p99_s;
    l.jitter_max_s = summary.loop.jitter_max_s;
    e.loop = l;
  }
  return e;
}

bool IsStaleWrite(const Status& st) { return db::ClassifyWrite(st) == db::WriteFault::kFenced; }

namespace {

// The final state a run's summary maps to; the one place that decides it.
db::RunStatus StatusOf(experiment::RunSummary::Termination t) {
  switch (t) {
    case experiment::RunSummary::Termination::kCancelled: return db::RunStatus::kCancelled;
    case experiment::RunSummary::Termination::kFailed: return db::RunStatus::kFailed;
    default: return db::RunStatus::kDone;
  }
}

// A block of the trace as a store chunk (all channels, channel-major).
void FillChunk(const experiment::Trace& block, std::int32_t index, db::TraceChunk* chunk) {
  const std::size_t n = block.size();
  chunk->index = index;
  chunk->t0_s = block.t_s[0];
  chunk->sample_period_s = block.sample_period_s;
  chunk->samples = static_cast<std::int32_t>(n);
  chunk->data.resize(chunk->channels.size() * n);
  for (std::size_t c = 0; c < chunk->channels.size(); ++c)
    for (std::size_t k = 0; k < n; ++k) chunk->data[c * n + k] = block.Value(c, k);
}

// The trace's blocks into the host's spool (runs/spool.h), on the trace stream's thread: the stream waits on
// the local disk only. A journal that cannot be written stops the stream (the run fails with the reason).
class SpoolChunks final : public experiment::BlockSink {
 public:
  explicit SpoolChunks(Journal* journal) : journal_(journal) { chunk_.channels = experiment::Trace::ChannelNames(); }
  Status OnBlock(const experiment::Trace& block, std::uint64_t /*first_sample*/) override {
    if (block.size() == 0) return Status::Ok();
    FillChunk(block, index_++, &chunk_);
    error_ = journal_->AppendChunk(chunk_);
    return error_;
  }
  const Status& error() const { return error_; }

 private:
  Journal* journal_;
  db::TraceChunk chunk_;
  std::int32_t index_ = 0;
  Status error_;
};

// The trace's blocks as store chunks, appended with the run's lease while the run executes (on the trace
// stream's thread; the worker's thread does not touch the store until the Runner returns). A chunk the store
// cannot take now (unavailable) is kept, in order, and written before the next one; the loop is not held up
// by the retries. Past kMaxBacklog chunks kept the stream stops (the run cannot be recorded: it is released).
class StoreChunks final : public experiment::BlockSink {
 public:
  static constexpr std::size_t kMaxBacklog = 64;  // chunks of up to 16384 samples x 12 channels: ~100 MB

  StoreChunks(db::Store* store, db::Lease lease, FaultLog* faults)
      : store_(store), lease_(lease), faults_(faults) {
    chunk_.channels = experiment::Trace::ChannelNames();
  }
  Status OnBlock(const experiment::Trace& block, std::uint64_t /*first_sample*/) override {
    if (block.size() == 0) return Status::Ok();
    FillChunk(block, index_++, &chunk_);
    if (backlog_.empty()) {
      const auto call_began = FaultLog::Clock::now();
      const Status st = store_->AppendTraceChunk(lease_, chunk_);
      if (db::ClassifyWrite(st) != db::WriteFault::kTransient) {
        if (st.ok() && faults_ != nullptr) faults_->Recovered();
        error_ = st;
        return error_;
      }
      if (faults_ != nullptr) faults_->Failed(st, call_began);
      last_transient_ = st;
      backlog_.push_back(chunk_);
    } else {
      backlog_.push_back(chunk_);  // after the ones kept before it, then one try to write them all
      error_ = TryFlush();
      if (!error_.ok()) return error_;
    }
    if (backlog_.size() > kMaxBacklog) error_ = last_transient_;
    return error_;
  }
  // Writes the kept chunks, once each in order, stopping at the first that fails transiently. Ok then (they
  // stay kept); a fenced or permanent refusal is returned.
  Status TryFlush() {
    while (!backlog_.empty()) {
      const auto call_began = FaultLog::Clock::now();
      const Status st = store_->AppendTraceChunk(lease_, backlog_.front());
      // AlreadyExists for a kept chunk (each was tried before): that earlier try committed and only its
      // answer was lost.
      if (st.ok() || st.code() == StatusCode::kAlreadyExists) {
        if (faults_ != nullptr) faults_->Recovered();
        backlog_.pop_front();
        continue;
      }
      if (db::ClassifyWrite(st) != db::WriteFault::kTransient) return st;
      if (faults_ != nullptr) faults_->Failed(st, call_began);
      last_transient_ = st;
      return Status::Ok();
    }
    return Status::Ok();
  }
  // After the run: the kept chunks, retried per `policy`. Ok when every chunk is stored.
  Status Flush(const RetryPolicy& policy) {
    if (!error_.ok() || backlog_.empty()) return error_;
    return RetryWrite(
        [&]() -> Status {
          VB_RETURN_IF_ERROR(TryFlush());
          return backlog_.empty() ? Status::Ok() : last_transient_;
        },
        policy, faults_);
  }
  // The store's refusal, if it refused a chunk (then the stream stopped and the Runner failed the run).
  const Status& error() const { return error_; }
  std::size_t kept() const { return backlog_.size(); }

 private:
  db::Store* store_;
  db::Lease lease_;
  FaultLog* faults_;
  db::TraceChunk chunk_;
  std::int32_t index_ = 0;
  std::deque<db::TraceChunk> backlog_;
  Status last_transient_;
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

// The store stayed unavailable past the retry policy's bound (or the server is stopping): the result is
// dropped, not written as a failure. The run stays running under a lease nobody renews (ExecuteContext::ended),
// so it lapses and the lab re-runs it (on one machine: the next start re-queues it).
Outcome Released(Outcome out, const db::RunRecord& run, const Status& st, const char* what) {
  spdlog::warn("run {} (fence {}): {} not written, the store stayed unavailable: {}; the run is released (its "
               "lease lapses and the lab runs it again)",
               static_cast<long long>(run.id), static_cast<long long>(run.fence), what, st.message());
  out.released = true;
  out.recorded = false;
  out.status = db::RunStatus::kRunning;
  return out;
}

// The end of a spooled run: its progress and result go to the journal, and the spool's uploader writes them
// after its chunks. Waits up to the policy's give_up_s for them to land; past that (or at a shutdown) the result
// stays in the spool, uploaded when the store takes it or by the next start (DrainLeftovers): never dropped.
Outcome SpoolResult(Outcome out, const db::RunRecord& run, const experiment::Experiment& e, Journal* journal,
                    db::Store* store, const RetryPolicy& policy) {
  if (out.summary.termination != experiment::RunSummary::Termination::kDone && out.summary.samples > 0 &&
      out.summary.last_sample_t_s < out.summary.duration_s) {
    out.summary.duration_s = out.summary.last_sample_t_s;
    if (out.summary.termination == experiment::RunSummary::Termination::kCancelled)
      out.summary.message = "cancelled at t = " + FormatNumber(out.summary.duration_s) + " s of " +
                            FormatNumber(e.duration_s) + " s";
  }
  SpooledResult res;
  if (out.summary.termination != experiment::RunSummary::Termination::kDone && e.duration_s > 0)
    res.progress = std::clamp(out.summary.duration_s / e.duration_s, 0.0, 1.0);
  res.status = StatusOf(out.summary.termination);
  res.reason = out.summary.message;
  if (res.status == db::RunStatus::kCancelled) {
    if (auto row = store->GetRun(run.id); row.ok() && !row->reason.empty()) res.reason = row->reason + "; " + res.reason;
  }
  res.metrics = RecordedMetrics(out.summary.metrics);
  res.execution = RecordedExecution(out.summary);
  out.status = res.status;
  out.reason = res.reason;
  if (Status st = journal->AppendResult(res); !st.ok())
    spdlog::warn("run {}: its result is not in the spool's file ({}); it is uploaded from memory", static_cast<long long>(run.id),
                 st.message());
  switch (journal->WaitForResult(policy.give_up_s, policy.stop)) {
    case Journal::State::kLanded: {
      const SpooledResult landed = journal->landed();
      out.status = landed.status;
      out.reason = landed.reason;
      out.recorded = true;
      return out;
    }
    case Journal::State::kFenced:
      return Stale(std::move(out), run, journal->fenced_status());
    default:
      spdlog::warn("run {} (fence {}): its result waits in the spool for the store; the spool uploads it when the "
                   "store takes it", static_cast<long long>(run.id), static_cast<long long>(run.fence));
      out.spooled = true;
      out.recorded = false;
      out.status = db::RunStatus::kRunning;
      return out;
  }
}

}  // namespace

Outcome Execute(db::Store* store, const db::RunRecord& run, const BenchSetup& setup, const ExecuteContext& ctx) {
  Outcome out;
  out.run_id = run.id;
  RetryPolicy policy = ctx.retry;
  policy.stop = ctx.stop;
  bool ended_called = false;
  auto finish = [&](db::RunStatus status, std::string reason, const std::vector<db::Metric>& metrics,
                    const std::optional<db::ExecutionRecord>& execution = std::nullopt) {
    out.status = status;
    out.reason = std::move(reason);
    // A run that never started still reads as failed, with the reason, to whoever looks at the summary.
    if (status == db::RunStatus::kFailed && out.summary.termination != experiment::RunSummary::Termination::kFailed &&
        out.summary.samples == 0) {
      out.summary.termination = experiment::RunSummary::Termination::kFailed;
      out.summary.message = out.reason;
    }
    if (!ended_called) {
      ended_called = true;
      if (ctx.ended) ctx.ended();
    }
    auto st = RetryWrite([&] { return store->Finish(db::LeaseOf(run), status, out.reason, metrics, execution); },
                         policy, ctx.faults);
    out.recorded = st.ok();
    switch (db::ClassifyWrite(st)) {
      case db::WriteFault::kNone:
        break;
      case db::WriteFault::kFenced:
        out.stale = true;
        spdlog::warn("run {} (fence {}): result not recorded, the run is no longer this attempt's: {}",
                     static_cast<long long>(run.id), static_cast<long long>(run.fence), st.message());
        break;
      case db::WriteFault::kTransient:
        return Released(std::move(out), run, st, "its result");
      case db::WriteFault::kPermanent: {
        // Bad data or a bug (not the transport): the run fails with the reason rather than staying running.
        spdlog::error("run {}: cannot record the result: {}", static_cast<long long>(run.id), st.message().c_str());
        const std::string why = "cannot record the result: " + st.message();
        if (status != db::RunStatus::kFailed || !metrics.empty() || execution) {
          auto failed = RetryWrite([&] { return store->Finish(db::LeaseOf(run), db::RunStatus::kFailed, why, {}); },
                                   policy, ctx.faults);
          if (failed.ok()) {
            out.status = db::RunStatus::kFailed;
            out.reason = why;
            out.recorded = true;
          }
        }
        break;
      }
    }
    return std::move(out);
  };
  const bool stopping = ctx.stop != nullptr && ctx.stop->load();

  // 1. The stored spec, with the bench's configured model as the plant.
  auto spec = experiment::ParseSpecJson(run.spec_json);
  if (!spec.ok()) return finish(db::RunStatus::kFailed, "stored spec does not parse: " + spec.status().message(), {});
  if (setup.kind == BenchKind::kEmulated && !setup.plant_from_spec) *spec->mutable_bench()->mutable_model() = setup.model;
  if (setup.paced) spec->set_realtime(true);

  // 2. The experiment and the bench.
  auto e = experiment::BuildExperiment(*spec);
  if (!e.ok()) return finish(db::RunStatus::kFailed, e.status().message(), {});
  auto opened = OpenBench(setup, *e);
  if (!opened.ok()) {
    out.bench_fault = true;
    return finish(db::RunStatus::kFailed, "bench " + setup.name + ": " + opened.status().message(), {});
  }
  // A trip puts the bench in its safe state and fails the run with the reason, keeping the samples up to it.
  std::unique_ptr<hw::SafetyBench> safety;
  hw::Bench* bench = opened->get();
  if (setup.interlocks) {
    safety = std::make_unique<hw::SafetyBench>(opened->get(), setup.safety);
    bench = safety.get();
  }

  // The run's journal in the host's spool, before the bench is driven: a spool that cannot be written is the
  // host's fault, said as such (the run fails with the reason and the bench is marked faulted).
  std::shared_ptr<Journal> journal;
  if (ctx.spool != nullptr) {
    auto begun = ctx.spool->Begin(db::LeaseOf(run));
    if (!begun.ok()) {
      bench->SafeState();
      out.bench_fault = true;
      spdlog::error("run {}: {}", static_cast<long long>(run.id), begun.status().message());
      return finish(db::RunStatus::kFailed, "bench " + setup.name + ": " + begun.status().message(), {});
    }
    journal = std::move(*begun);
  }

  // 3. Run it, visible to watchers.
  experiment::RunMonitor monitor;
  const int decimation = std::max(1, static_cast<int>(std::lround(e->run.sample_rate_Hz / 1000.0)));
  LiveTap tap(decimation, &e->reference);
  if (ctx.registry != nullptr) ctx.registry->Add(run.id, &monitor, &tap, e->duration_s);
  if (ctx.current_monitor != nullptr) ctx.current_monitor->store(&monitor);
  const auto cancel_asked = FaultLog::Clock::now();
  auto cancel_requested = store->CancelRequested(run.id);
  // Only read to start a run already cancelled as cancelled; unavailable, the run starts (the lab thread reads
  // cancels again every 0.1 s), but the fault is counted.
  if (ctx.faults != nullptr && db::ClassifyWrite(cancel_requested.status()) == db::WriteFault::kTransient)
    ctx.faults->Failed(cancel_requested.status(), cancel_asked);
  if (stopping || (cancel_requested.ok() && *cancel_requested)) monitor.cancel.store(true);
  bench->set_cancel_flag(&monitor.cancel);  // cancel and shutdown stop a long bench step (hw::Bench)
  StoreChunks chunks(store, db::LeaseOf(run), ctx.faults);
  std::unique_ptr<SpoolChunks> spooled;
  if (journal != nullptr) spooled = std::make_unique<SpoolChunks>(journal.get());
  experiment::RunOptions options;
  options.monitor = &monitor;
  options.extra_sink = ctx.registry != nullptr ? &tap : nullptr;
  options.block_sink = spooled != nullptr ? static_cast<experiment::BlockSink*>(spooled.get()) : &chunks;
  options.block_samples = db::kDefaultChunkSamples;
  options.keep_whole_trace = ctx.keep_trace;
  out.summary = experiment::Runner::Run(*e, *bench, &out.trace, options);
  bench->SafeState();
  if (safety != nullptr && safety->tripped()) out.bench_fault = true;
  if (spooled != nullptr && !spooled->error().ok()) {
    // The run stopped because the host's disk would not take its trace: the host's fault, with the reason.
    out.bench_fault = true;
    spdlog::error("run {}: stopped, its trace cannot be spooled: {}", static_cast<long long>(run.id),
                  spooled->error().message());
  }
  if (out.summary.loop.ticks > 0)
    spdlog::info("run {}: loop: {} paced ticks, {} overruns, jitter p50 {:.1f} us, p99 {:.1f} us, max {:.1f} us; "
                 "{} wait(s) for the recording",
                 static_cast<long long>(run.id), out.summary.loop.ticks, out.summary.loop.overruns,
                 out.summary.loop.jitter_p50_s * 1e6, out.summary.loop.jitter_p99_s * 1e6,
                 out.summary.loop.jitter_max_s * 1e6, out.summary.record_waits);
  if (ctx.current_monitor != nullptr) {
    std::unique_lock<std::mutex> lock;
    if (ctx.current_monitor_mu != nullptr) lock = std::unique_lock<std::mutex>(*ctx.current_monitor_mu);
    ctx.current_monitor->store(nullptr);
  }
  if (ctx.registry != nullptr) ctx.registry->Remove(run.id, &monitor);
  ended_called = true;
  if (ctx.ended) ctx.ended();

  if (ctx.stop != nullptr && ctx.stop->load() &&
      out.summary.termination == experiment::RunSummary::Termination::kCancelled) {
    out.status = db::RunStatus::kRunning;  // left for RecoverAfterCrash on the next start
    if (journal != nullptr) journal->Abandon();
    return out;
  }
  if (journal != nullptr) return SpoolResult(std::move(out), run, *e, journal.get(), store, policy);

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
  // The trace is in the store already, but for chunks kept while the store was unavailable: written now. A
  // chunk the store refused failed the run ("recording: ..."): as stale, as released (unavailable too long), or
  // as failed (bad data).
  if (Status st = chunks.Flush(policy); IsStaleWrite(st)) {
    return Stale(std::move(out), run, st);
  } else if (db::ClassifyWrite(st) == db::WriteFault::kTransient) {
    return Released(std::move(out), run, st, db::Cat(chunks.kept(), " trace chunk(s) and the result").c_str());
  }
  if (out.summary.termination != experiment::RunSummary::Termination::kDone && e->duration_s > 0) {
    const double reached = std::clamp(out.summary.duration_s / e->duration_s, 0.0, 1.0);
    if (auto st = RetryWrite([&] { return store->SetProgress(db::LeaseOf(run), reached); }, policy, ctx.faults);
        IsStaleWrite(st)) {
      return Stale(std::move(out), run, st);
    } else if (db::ClassifyWrite(st) == db::WriteFault::kTransient) {
      return Released(std::move(out), run, st, "its progress and result");
    } else if (!st.ok()) {
      spdlog::warn("run {}: cannot record its progress: {}", static_cast<long long>(run.id), st.message().c_str());
    }
  }
  db::RunStatus status = StatusOf(out.summary.termination);
  std::string reason = out.summary.message;
  // What the reader of the numbers must know (a recording below twice the carrier: docs/metrics.md), kept with
  // the run so `show`, the run page and Python say it too.
  for (const auto& w : out.summary.warnings) reason += (reason.empty() ? "" : "; ") + ("warning: " + w);
  if (status == db::RunStatus::kCancelled) {
    // Keep why it was cancelled (the request's reason, stored by RequestCancel), not only when.
    if (auto row = store->GetRun(run.id); row.ok() && !row->reason.empty()) reason = row->reason + "; " + reason;
  }
  return finish(status, std::move(reason), RecordedMetrics(out.summary.metrics), RecordedExecution(out.summary));
}

}  // namespace vb::runs
