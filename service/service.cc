#include "common/format.h"
#include "service/service.h"

#include <google/protobuf/util/json_util.h>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <cmath>
#include <cstring>
#include <optional>
#include <thread>

#include "common/decimate.h"
#include "db/open_store.h"
#include "db/run_query.h"
#include "experiment/compare.h"
#include "experiment/spec.h"
#include "hw/usb/list_attached.h"
#include "proto/api_convert.h"
#include "runs/query.h"
#include "service/grpc_status.h"
#include "service/lab_benches.h"

namespace vb::server {

namespace v1 = valvebench::v1;

StorePool::Handle::~Handle() {
  if (store_ == nullptr) return;
  pool_->Release(std::move(store_));
}

void StorePool::CloseStale(std::vector<std::unique_ptr<db::Store>>* out) {
  const auto now = Clock::now();
  for (auto it = free_.begin(); it != free_.end();) {
    if (std::chrono::duration<double>(now - it->since).count() > kIdle_s) {
      out->push_back(std::move(it->store));
      it = free_.erase(it);
      --open_;
    } else {
      ++it;
    }
  }
}

void StorePool::Release(std::unique_ptr<db::Store> s) {
  std::vector<std::unique_ptr<db::Store>> closing;  // closed outside the lock
  {
    std::lock_guard<std::mutex> lock(mu_);
    CloseStale(&closing);
    if (static_cast<int>(free_.size()) >= kMaxIdle) {
      closing.push_back(std::move(s));
      --open_;
    } else {
      free_.push_back({std::move(s), Clock::now()});
    }
  }
  returned_.notify_one();
}

StatusOr<StorePool::Handle> StorePool::Acquire() {
  std::vector<std::unique_ptr<db::Store>> closing;
  {
    std::unique_lock<std::mutex> lock(mu_);
    CloseStale(&closing);
    const bool room = returned_.wait_for(lock, std::chrono::duration<double>(kAcquireWait_s),
                                         [this] { return !free_.empty() || open_ < kMaxOpen; });
    if (!room)
      return Status::Unavailable("store: " + std::to_string(kMaxOpen) +
                                 " connections in use, the server's limit; try again in a moment");
    if (!free_.empty()) {  // the most recently used: the stale ones age out at the front
      auto s = std::move(free_.back().store);
      free_.pop_back();
      return Handle(this, std::move(s));
    }
    ++open_;  // taken now, opened below (outside the lock)
  }
  auto s = db::OpenStore(path_);  // a SQLite file or PostgreSQL
  if (!s.ok()) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      --open_;
    }
    returned_.notify_one();
    return s.status();
  }
  return Handle(this, std::move(s.value()));
}

int StorePool::open() const {
  std::lock_guard<std::mutex> lock(mu_);
  return open_;
}

int StorePool::idle() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int>(free_.size());
}

std::shared_ptr<void> StreamGate::Take(const std::string& user, const char* call, std::string* why) {
  std::lock_guard<std::mutex> lock(mu_);
  int& mine = per_user_[user];
  if (total_ >= kMax || mine >= kMaxPerUser) {
    *why = total_ >= kMax ? std::string(call) + ": the server has " + std::to_string(total_) +
                                " streams open, its limit; try again later"
                          : std::string(call) + ": user " + user + " has " + std::to_string(mine) +
                                " streams open, the limit per user; close some";
    if (mine == 0) per_user_.erase(user);
    return nullptr;
  }
  ++mine;
  ++total_;
  struct Slot {
    StreamGate* gate;
    std::string user;
    ~Slot() {
      std::lock_guard<std::mutex> lock(gate->mu_);
      --gate->total_;
      auto it = gate->per_user_.find(user);
      if (it != gate->per_user_.end() && --it->second <= 0) gate->per_user_.erase(it);
    }
  };
  return std::shared_ptr<void>(new Slot{this, user}, [](void* p) { delete static_cast<Slot*>(p); });
}

int StreamGate::open() const {
  std::lock_guard<std::mutex> lock(mu_);
  return total_;
}

grpc::Status BenchServiceImpl::SubmitRun(grpc::ServerContext* ctx, const v1::SubmitRunRequest* req,
                                         v1::SubmitRunResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  return Submit({who.user, req->batch_name().empty() ? req->spec().name() : req->batch_name(), {req->spec()}, {}, ""},
                resp);
}

grpc::Status BenchServiceImpl::SubmitBatch(grpc::ServerContext* ctx, const v1::SubmitBatchRequest* req,
                                           v1::SubmitRunResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (req->specs_size() == 0) return ToGrpcStatus(Status::InvalidArgument("specs: at least one spec is needed"));
  runs::Submission sub{who.user, req->batch_name(), {req->specs().begin(), req->specs().end()}, {}, ""};
  for (const auto& k : req->keys()) sub.keys.push_back(api::FromProto(k));
  return Submit(sub, resp);
}

StatusOr<runs::Queued> BenchServiceImpl::Queue(const runs::Submission& submission) {
  auto store = pool_->Acquire();
  if (!store.ok()) return store.status();
  // In a lab a run may go to any host's bench (docs/lab.md): admission matches against them all.
  runs::Policy lab_policy;
  if (settings_->lab.enabled) {
    auto hosts = (*store)->ListHosts();
    if (!hosts.ok()) return hosts.status();
    lab_policy = policy_;
    for (auto& b : OtherHostsBenches(*hosts, settings_->lab.host)) lab_policy.benches.push_back(std::move(b));
  }
  const runs::Policy& policy = settings_->lab.enabled ? lab_policy : policy_;
  auto admitted = runs::Admit(submission, policy);
  if (!admitted.ok()) return admitted.status();
  auto queued = runs::Enqueue(store->get(), std::move(admitted.value()), policy);
  if (queued.ok()) registry_->NotifyWork();
  return queued;
}

grpc::Status BenchServiceImpl::Submit(const runs::Submission& submission, v1::SubmitRunResponse* resp) {
  auto queued = Queue(submission);
  if (!queued.ok()) return ToGrpcStatus(queued.status());
  resp->set_batch_id(queued->batch_id);
  for (auto id : queued->run_ids) resp->add_run_ids(id);
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::FillRun(db::Store* store, const db::RunRecord& r, bool full, v1::Run* out) {
  out->set_id(r.id);
  out->set_batch_id(r.batch_id);
  out->set_name(r.key.DisplayName());
  *out->mutable_key() = api::ToProto(r.key);
  out->set_split(r.split);
  if (std::isfinite(r.t_start_s)) out->set_t_start_s(r.t_start_s);
  out->set_controller(r.controller);
  out->set_bench(r.bench_name);
  out->set_host(r.host);
  out->set_fence(r.fence);
  if (const auto spec = nlohmann::json::parse(r.spec_json, nullptr, false); spec.is_object())
    if (auto d = spec.find("duration_s"); d != spec.end() && d->is_number()) out->set_duration_s(d->get<double>());
  out->set_submitter(r.submitter);
  out->set_priority(r.priority);
  out->set_status(api::ToProto(r.status));
  out->set_reason(r.reason);
  out->set_submitted_unix_s(r.submitted_unix_s);
  out->set_started_unix_s(r.started_unix_s);
  out->set_finished_unix_s(r.finished_unix_s);
  double progress = r.status == db::RunStatus::kDone ? 1.0 : r.progress;
  if (r.status == db::RunStatus::kRunning) {
    registry_->Progress(r.id, &progress);
    out->set_result_waiting_since_unix_s(registry_->ResultWaitingSince(r.id));
  }
  out->set_progress(progress);
  for (const auto& t : r.tags) out->add_tags(t);
  if (r.execution) {
    const db::ExecutionRecord& e = *r.execution;
    auto* x = out->mutable_execution();
    x->set_wall_s(e.wall_s);
    x->set_simulated_s(e.simulated_s);
    x->set_samples(e.samples);
    x->set_control_ticks(e.control_ticks);
    x->set_metrics_from_trajectory(e.metrics_from_trajectory);
    x->set_build(e.build);
    if (e.loop) {
      auto* l = x->mutable_loop();
      l->set_ticks(e.loop->ticks);
      l->set_overruns(e.loop->overruns);
      l->set_jitter_p50_s(e.loop->jitter_p50_s);
      l->set_jitter_p99_s(e.loop->jitter_p99_s);
      l->set_jitter_max_s(e.loop->jitter_max_s);
    }
  }
  auto metrics = store->GetMetrics(r.id);
  if (!metrics.ok()) return ToGrpcStatus(metrics.status());
  for (const auto& m : *metrics) (*out->mutable_metrics())[m.name] = m.value;
  if (!full) return grpc::Status::OK;
  google::protobuf::util::JsonParseOptions opts;
  (void)google::protobuf::util::JsonStringToMessage(r.spec_json, out->mutable_spec(), opts);
  auto history = store->History(r.id);
  if (!history.ok()) return ToGrpcStatus(history.status());
  for (const auto& h : *history) {
    auto* c = out->add_history();
    c->set_status(api::ToProto(h.status));
    c->set_at_unix_s(h.at_unix_s);
    c->set_reason(h.reason);
  }
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::GetRun(grpc::ServerContext* ctx, const v1::GetRunRequest* req, v1::Run* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto r = (*store)->GetRun(req->run_id());
  if (!r.ok()) return ToGrpcStatus(r.status());
  return FillRun(store->get(), *r, true, resp);
}

grpc::Status BenchServiceImpl::ListRuns(grpc::ServerContext* ctx, const v1::ListRunsRequest* req,
                                        v1::ListRunsResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  db::RunFilter f;
  f.status = api::FromProto(req->status());
  // An unknown value (a newer client, a typo through a raw API) must not read as "any status" (issue 14).
  if (req->status() != v1::RUN_STATUS_UNSPECIFIED && !f.status.has_value())
    return ToGrpcStatus(Status::InvalidArgument("status: unknown run status " + std::to_string(req->status())));
  f.tag = req->tag();
  f.batch_id = req->batch_id();
  f.controller = req->controller();
  f.bench_name = req->bench();
  f.submitter = req->submitter();
  f.submitted_after_unix_s = req->submitted_after_unix_s();
  f.submitted_before_unix_s = req->submitted_before_unix_s();
  f.name = req->name();
  if (req->page_size() < 0 || req->page_size() > 1000)
    return ToGrpcStatus(Status::InvalidArgument("page_size: must be in [0, 1000] (0 = 100)"));
  f.limit = req->page_size() == 0 ? 100 : req->page_size();
  // Newest first unless asked otherwise; the page token carries a keyset cursor valid for this order and these
  // filters only (db/run_query.h).
  auto order = db::ParseRunOrder(req->order_by());
  if (!order.ok()) return ToGrpcStatus(order.status());
  f.order = *order;
  if (auto st = db::ApplyPageToken(req->page_token(), &f); !st.ok()) return ToGrpcStatus(st);
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto runs = (*store)->ListRuns(f);
  if (!runs.ok()) return ToGrpcStatus(runs.status());
  auto total = (*store)->CountRuns(f);
  if (!total.ok()) return ToGrpcStatus(total.status());
  resp->set_total_size(*total);
  for (const auto& r : *runs)
    if (auto st = FillRun(store->get(), r, false, resp->add_runs()); !st.ok()) return st;
  if (static_cast<std::int32_t>(runs->size()) == f.limit) resp->set_next_page_token(db::EncodePageToken(f, runs->back()));
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::CancelRun(grpc::ServerContext* ctx, const v1::CancelRunRequest* req, v1::Run* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto r = (*store)->GetRun(req->run_id());
  if (!r.ok()) return ToGrpcStatus(r.status());
  if (r->submitter != who.user && !who.AtLeast(Role::kAdmin))
    return PermissionDenied("user " + who.user + " may cancel only their own runs (run " +
                            std::to_string(r->id) + " is " + r->submitter + "'s)");
  // Who cancelled is always recorded, from the token, ahead of the caller's own words (which cannot replace it).
  std::string words = req->reason();
  if (words.size() > 500) {
    size_t cut = 500;
    while (cut > 0 && (static_cast<unsigned char>(words[cut]) & 0xC0) == 0x80) --cut;  // not inside a UTF-8 character
    words.resize(cut);
  }
  auto st = (*store)->RequestCancel(r->id, "cancelled by " + who.user + (words.empty() ? "" : ": " + words));
  if (!st.ok()) return ToGrpcStatus(st.status());
  if (*st == db::RunStatus::kRunning) {
    registry_->Cancel(r->id);
    // The loop stops within one control period; wait briefly so the answer shows the final state.
    for (int k = 0; k < 100; ++k) {
      auto now = (*store)->GetRun(r->id);
      if (now.ok() && Ended(now->status)) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  auto now = (*store)->GetRun(r->id);
  if (!now.ok()) return ToGrpcStatus(now.status());
  return FillRun(store->get(), *now, true, resp);
}

namespace {

constexpr int kStoredSamplePolls = 5;  // a run on another host: its stored chunks are read every 5th poll (4 Hz)

// Samples of the stored trace chunks from *next_chunk on, thinned, into ev; advances *next_chunk.
Status StoredSamples(db::Store* store, std::int64_t run_id, std::int32_t* next_chunk, runs::SampleThinner* thinner,
                     v1::RunEvent* ev) {
  return store->ForEachTraceChunk(run_id, [&](const db::TraceChunk& c, std::int64_t) {
    if (c.index < *next_chunk) return Status::Ok();
    auto column = [&](const char* name) -> const double* {
      for (std::size_t k = 0; k < c.channels.size(); ++k)
        if (c.channels[k] == name) return c.data.data() + k * static_cast<std::size_t>(c.samples);
      return nullptr;
    };
    const double* t = column("t_s");
    const double* gate = column("gate");
    const double* i = column("i_A");
    const double* x = column("x_m");
    const double* ref = column("ref");
    for (std::int32_t k = 0; k < c.samples; ++k) {
      const double t_s = t != nullptr ? t[k] : c.t0_s + k * c.sample_period_s;
      const int g = gate != nullptr ? static_cast<int>(gate[k]) : 0;
      double duty = 0.0;
      std::uint64_t lost = 0;
      // Each stored sample is one recorded sample: the duty is their mean (the stored trace has no on-time).
      if (!thinner->Keep(t_s, g != 0 ? 1.0 : 0.0, 0, &duty, &lost)) continue;
      auto* ls = ev->add_samples();
      ls->set_t_s(t_s);
      ls->set_gate(g);
      ls->set_duty(duty);
      ls->set_i_a(i != nullptr ? i[k] : std::nan(""));
      ls->set_x_m(x != nullptr ? x[k] : std::nan(""));
      ls->set_ref(ref != nullptr ? ref[k] : std::nan(""));
    }
    *next_chunk = c.index + 1;
    return Status::Ok();
  });
}

}  // namespace

grpc::Status BenchServiceImpl::WatchRun(grpc::ServerContext* ctx, const v1::WatchRunRequest* req,
                                        grpc::ServerWriter<v1::RunEvent>* writer) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  std::string full;
  const auto slot = streams_.Take(who.user, "WatchRun", &full);
  if (!slot) return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, full);
  if (!std::isfinite(req->sample_rate_hz()))
    return ToGrpcStatus(Status::InvalidArgument("sample_rate_Hz: must be finite (0 = no live samples)"));
  runs::SampleThinner thinner(req->sample_rate_hz());
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  std::uint64_t seq = 0;
  bool seq_started = false;         // samples before this watch's first read are not its losses
  std::uint64_t dropped = 0;        // live samples this watch lost (RunEvent.dropped_samples)
  std::int32_t next_chunk = 0;      // a run on another host: the first stored chunk not yet sent
  std::int64_t watched_fence = -1;
  int polls = 0;
  bool first = true;
  db::RunStatus last_status = db::RunStatus::kQueued;
  double last_progress = -1.0;
  std::int64_t last_fence = -1;     // the attempt the last event was about (RunRecord::fence)
  // An interactive run watched by its submitter is cancelled when that watch goes away before the run ends.
  bool owns_interactive = false;
  if (auto r = (*store)->GetRun(req->run_id()); r.ok() && r->submitter == who.user) {
    v1::ExperimentSpec spec;
    google::protobuf::util::JsonParseOptions opts;
    opts.ignore_unknown_fields = true;
    owns_interactive = google::protobuf::util::JsonStringToMessage(r->spec_json, &spec, opts).ok() && spec.interactive();
  }
  auto client_gone = [&]() {
    if (!owns_interactive) return;
    auto st = (*store)->RequestCancel(req->run_id(), "client disconnected from an interactive run");
    if (st.ok() && *st == db::RunStatus::kRunning) registry_->Cancel(req->run_id());  // safe state now
  };
  while (!ctx->IsCancelled()) {
    auto r = (*store)->GetRun(req->run_id());
    if (!r.ok()) return ToGrpcStatus(r.status());
    v1::RunEvent ev;
    ev.set_run_id(r->id);
    ev.set_status(api::ToProto(r->status));
    ev.set_reason(r->reason);
    double progress = r->status == db::RunStatus::kDone ? 1.0 : r->progress;
    if (r->status == db::RunStatus::kRunning) {
      const bool here = registry_->Progress(r->id, &progress);
      if (!here && req->sample_rate_hz() > 0.0 && ++polls % kStoredSamplePolls == 0) {
        // Executing on another host of the lab: its progress comes from the store (that host writes it), and
        // samples from the trace chunks stored so far (docs/lab.md, "Watching a run on another host").
        if (r->fence != watched_fence) {  // a new attempt writes its trace from chunk 0 again
          watched_fence = r->fence;
          next_chunk = 0;
        }
        if (auto st = StoredSamples(store->get(), r->id, &next_chunk, &thinner, &ev); !st.ok())
          spdlog::warn("watch of run {}: stored trace not readable yet: {}", static_cast<long long>(r->id),
                       st.message());
      }
      if (here && req->sample_rate_hz() > 0.0) {  // 0 (or less): no live samples (proto: "0 = none")
        std::vector<runs::LiveSample> samples;
        registry_->SamplesSince(r->id, &seq, &samples, seq_started ? &dropped : nullptr);
        seq_started = true;
        for (const auto& s : samples) {
          // Losses before a thinned-out sample are carried to the next kept one (thinning is not a loss).
          double duty = 0.0;
          std::uint64_t lost = 0;
          if (!thinner.Keep(s.t_s, s.duty, s.dropped_before, &duty, &lost)) continue;
          dropped += lost;
          auto* ls = ev.add_samples();
          ls->set_t_s(s.t_s);
          ls->set_gate(s.gate);
          ls->set_duty(duty);
          ls->set_i_a(s.i_A);
          ls->set_x_m(s.x_m);
          ls->set_ref(s.ref);
        }
      }
    }
    // One attempt's progress never goes back: between the loop's end (the registry forgets the run) and its result
    // reaching the store (the spool, docs/lab.md) the store still says running with the progress it last stored,
    // which may be older than what this stream already sent (CI saw 62 %, then 0 %, then done). A new attempt
    // (another fence) starts again from what it reports.
    if (r->status == db::RunStatus::kRunning && last_status == db::RunStatus::kRunning && r->fence == last_fence)
      progress = std::max(progress, last_progress);
    last_fence = r->fence;
    ev.set_progress(progress);
    ev.set_dropped_samples(static_cast<std::int64_t>(dropped));
    const bool changed = first || r->status != last_status || std::abs(progress - last_progress) >= 0.01 ||
                         ev.samples_size() > 0;
    if (changed && !writer->Write(ev)) {  // the client went away
      if (!Ended(r->status)) client_gone();
      return grpc::Status::OK;
    }
    first = false;
    last_status = r->status;
    last_progress = progress;
    if (Ended(r->status) || r->status == db::RunStatus::kInterrupted) return grpc::Status::OK;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  client_gone();
  return grpc::Status(grpc::StatusCode::CANCELLED, "watch cancelled by the client");
}

grpc::Status BenchServiceImpl::GetTrace(grpc::ServerContext* ctx, const v1::GetTraceRequest* req,
                                        grpc::ServerWriter<v1::TraceChunk>* writer) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  std::string full;
  const auto slot = streams_.Take(who.user, "GetTrace", &full);
  if (!slot) return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, full);
  if (auto st = CheckDecimation(req->max_points(), req->from_s(), req->to_s()); !st.ok()) return ToGrpcStatus(st);
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto r = (*store)->GetRun(req->run_id());
  if (!r.ok()) return ToGrpcStatus(r.status());
  if (!Ended(r->status))
    return ToGrpcStatus(Status::FailedPrecondition("run " + std::to_string(r->id) + " is " +
                                                   db::RunStatusName(r->status) +
                                                   "; its trace is stored when it ends"));
  // Stream while reading: chunk k goes out while chunk k+1 is read; only one stored chunk (and, decimating,
  // the rows not yet sent) is ever in memory.
  v1::TraceChunk out;
  bool client_gone = false;
  auto send = [&]() {
    if (writer->Write(out)) return Status::Ok();
    client_gone = true;
    return Status::Aborted("client went away");
  };
  const bool windowed = req->from_s() != 0.0 || req->to_s() != 0.0;
  if (req->max_points() == 0 && !windowed) {
    auto st = (*store)->ForEachTraceChunk(r->id, [&](const db::TraceChunk& c, std::int64_t total) {
      if (ctx->IsCancelled()) return Status::Aborted("cancelled by the client");
      out.Clear();
      out.set_index(c.index);
      out.set_t0_s(c.t0_s);
      out.set_sample_period_s(c.sample_period_s);
      out.set_samples(c.samples);
      out.set_total_samples(total);
      for (const auto& ch : c.channels) out.add_channels(ch);
      out.set_data(reinterpret_cast<const char*>(c.data.data()), c.data.size() * sizeof(double));
      return send();
    });
    if (client_gone) return grpc::Status::OK;
    if (!st.ok()) return ToGrpcStatus(st);
    return grpc::Status::OK;
  }
  // A window and/or decimation (common/decimate.h): the samples of [from_s, to_s], min/max-decimated to
  // max_points rows when max_points > 0 and the window holds more.
  std::optional<MinMaxDecimator> decimator;
  std::vector<std::size_t> kept;  // the stored channels sent (decimating: all but t_s, whose times are in t_s)
  std::vector<std::string> names;
  SampleWindow window;
  double t0_s = 0.0, period_s = 0.0;
  std::int64_t total_samples = 0, k = 0;
  std::int32_t index = 0;
  std::size_t rows_per_chunk = 1;
  bool window_read = false, first = true;
  auto header = [&](std::int32_t samples) {
    out.Clear();
    out.set_index(index++);
    out.set_sample_period_s(period_s);
    out.set_samples(samples);
    out.set_total_samples(total_samples);
    for (const auto& n : names) out.add_channels(n);
  };
  auto send_rows = [&](bool all) {
    while (decimator->pending_rows() >= rows_per_chunk || (all && decimator->pending_rows() > 0)) {
      MinMaxDecimator::Rows rows = decimator->TakeRows();
      // Chunks of at most rows_per_chunk rows (a gRPC message stays far below its 4 MB limit).
      for (std::size_t at = 0; at < rows.t_s.size(); at += rows_per_chunk) {
        const std::size_t m = std::min(rows_per_chunk, rows.t_s.size() - at);
        header(static_cast<std::int32_t>(m));
        out.set_t0_s(t0_s);
        out.set_decimated(decimator->decimating());
        out.mutable_t_s()->Add(rows.t_s.begin() + static_cast<std::ptrdiff_t>(at),
                               rows.t_s.begin() + static_cast<std::ptrdiff_t>(at + m));
        std::string* data = out.mutable_data();
        data->resize(m * kept.size() * sizeof(double));
        for (std::size_t j = 0; j < kept.size(); ++j)
          std::memcpy(data->data() + j * m * sizeof(double), rows.values[j].data() + at, m * sizeof(double));
        VB_RETURN_IF_ERROR(send());
      }
    }
    return Status::Ok();
  };
  auto st = (*store)->ForEachTraceChunk(r->id, [&](const db::TraceChunk& c, std::int64_t total) {
    if (ctx->IsCancelled()) return Status::Aborted("cancelled by the client");
    const auto n = static_cast<std::int64_t>(c.samples);
    if (first) {
      first = false;
      t0_s = c.t0_s;
      period_s = c.sample_period_s;
      total_samples = total;
      window = WindowOf(t0_s, period_s, total, req->from_s(), req->to_s());
      for (std::size_t ch = 0; ch < c.channels.size(); ++ch)
        if (req->max_points() == 0 || c.channels[ch] != "t_s") {
          kept.push_back(ch);
          names.push_back(c.channels[ch]);
        }
      if (req->max_points() > 0) {
        decimator.emplace(kept.size(), window, req->max_points(), t0_s, period_s);
        rows_per_chunk = std::max<std::size_t>(1, (1u << 20) / ((kept.size() + 1) * sizeof(double)));
      }
    }
    if (c.channels.size() * static_cast<std::size_t>(n) != c.data.size())
      return Status::DataLoss("trace chunk " + std::to_string(c.index) + ": data size does not match");
    if (decimator) {
      for (std::int64_t i = std::max<std::int64_t>(0, window.k0 - k); i < n && k + i < window.k1; ++i)
        decimator->Add(k + i, [&](std::size_t j) { return c.data[kept[j] * static_cast<std::size_t>(n) + i]; });
      VB_RETURN_IF_ERROR(send_rows(false));
    } else {
      const std::int64_t lo = std::max(k, window.k0), hi = std::min(k + n, window.k1);
      if (hi > lo) {
        const auto m = static_cast<std::size_t>(hi - lo);
        header(static_cast<std::int32_t>(m));
        out.set_t0_s(t0_s + static_cast<double>(lo) * period_s);
        std::string* data = out.mutable_data();
        data->resize(m * kept.size() * sizeof(double));
        for (std::size_t j = 0; j < kept.size(); ++j)
          std::memcpy(data->data() + j * m * sizeof(double),
                      c.data.data() + kept[j] * static_cast<std::size_t>(n) + static_cast<std::size_t>(lo - k),
                      m * sizeof(double));
        VB_RETURN_IF_ERROR(send());
      }
    }
    k += n;
    if (k >= window.k1) {
      window_read = true;  // the rest of the trace is after the window: stop reading
      return Status::Aborted("window read");
    }
    return Status::Ok();
  });
  if (client_gone) return grpc::Status::OK;
  if (!st.ok() && !window_read) return ToGrpcStatus(st);
  if (decimator) {
    decimator->Finish();
    if (auto sent = send_rows(true); !sent.ok()) return grpc::Status::OK;  // the client went away
  }
  if (index == 0) {  // nothing in the window (or no trace): one empty chunk still names the channels
    header(0);
    out.set_t0_s(t0_s);
    if (!writer->Write(out)) return grpc::Status::OK;
  }
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::CompareRuns(grpc::ServerContext* ctx, const v1::CompareRunsRequest* req,
                                           v1::CompareRunsResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if ((req->batch_id() == 0) == (req->run_ids_size() == 0))
    return ToGrpcStatus(Status::InvalidArgument("batch_id, run_ids: give a batch or a list of runs"));
  // A comparison is a table for people; 100 k ids cost the server ~1 s and 125 MB (issue 14). A batch is
  // bounded by limits.max_runs_per_submission already.
  constexpr int kMaxCompareRuns = 1000;
  if (req->run_ids_size() > kMaxCompareRuns)
    return ToGrpcStatus(Status::InvalidArgument("run_ids: at most " + std::to_string(kMaxCompareRuns) +
                                                " runs per comparison, got " + std::to_string(req->run_ids_size())));
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto runs = req->batch_id() != 0
                  ? runs::ListBatch(store->get(), req->batch_id())
                  : runs::GetRuns(store->get(), {req->run_ids().begin(), req->run_ids().end()});
  if (!runs.ok()) return ToGrpcStatus(runs.status());
  auto compared = runs::CompareStored(store->get(), *runs);
  if (!compared.ok()) return ToGrpcStatus(compared.status());
  const experiment::Comparison& c = *compared;
  resp->set_rank_metric(c.rank_metric);
  resp->set_effort_metric(c.effort_metric);
  for (const auto& col : c.columns) resp->add_columns(col);
  for (const auto& row : c.rows) {
    auto* out = resp->add_rows();
    out->set_rank(row.rank);
    out->set_name(row.name);
    *out->mutable_key() = api::ToProto(row.key);
    for (auto id : row.run_ids) out->add_run_ids(id);
    out->set_controller(row.controller);
    out->set_runs(row.runs);
    out->set_failed(row.failed);
    out->set_pareto(row.pareto);
    for (const auto& [name, stat] : row.metrics) {
      if (stat.n == 0) continue;
      v1::MetricStat ms;
      ms.set_mean(stat.mean);
      ms.set_spread(stat.spread);
      ms.set_n(stat.n);
      (*out->mutable_metrics())[name] = ms;
    }
  }
  return grpc::Status::OK;
}

// Every host's benches (docs/lab.md, "Hosts"): what each host last wrote with its heartbeat, its liveness
// (heartbeat age against the lease TTL: a host silent for longer has lost its leases), and the run each bench is
// executing according to the store.
grpc::Status BenchServiceImpl::LabBenches(v1::ListBenchesResponse* resp) {
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto hosts = (*store)->ListHosts();
  if (!hosts.ok()) return ToGrpcStatus(hosts.status());
  std::map<std::pair<std::string, std::string>, std::int64_t> running;  // (host, bench) -> run
  db::RunFilter f;
  f.status = db::RunStatus::kRunning;
  f.limit = 1000;
  for (;;) {
    auto page = (*store)->ListRuns(f);
    if (!page.ok()) return ToGrpcStatus(page.status());
    for (const auto& r : *page) running[{r.host, r.bench_name}] = r.id;
    if (static_cast<int>(page->size()) < f.limit) break;
    f.after_id = page->back().id;
  }
  const double now =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  for (const auto& h : *hosts) {
    const auto benches = nlohmann::json::parse(h.benches_json, nullptr, false);
    if (!benches.is_array()) continue;
    const double age = std::max(0.0, now - h.heartbeat_unix_s);
    for (const auto& b : benches) {
      auto info = RegisteredBench(b.dump());
      if (!info.ok()) continue;  // not a bench description: nothing to list
      auto* out = resp->add_benches();
      *out = std::move(*info);
      out->set_host(h.name);
      out->set_host_address(h.address);
      out->set_heartbeat_age_s(age);
      out->set_alive(age <= settings_->lab.lease_ttl_s);
      if (auto it = running.find({h.name, out->name()}); it != running.end()) {
        out->set_busy(true);
        out->set_current_run_id(it->second);
      }
    }
  }
  return grpc::Status::OK;
}

grpc::Status BenchServiceImpl::ListBenches(grpc::ServerContext* ctx, const v1::ListBenchesRequest* /*req*/,
                                           v1::ListBenchesResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (settings_->lab.enabled) {
    if (auto st = LabBenches(resp); !st.ok()) return st;
  }
  static const std::vector<std::unique_ptr<runs::Worker>> kNone;
  for (const auto& w : settings_->lab.enabled ? kNone : *workers_) {
    auto* out = resp->add_benches();
    *out = DescribeBench(w->setup());
    out->set_fault(w->fault());
    const auto current = w->current_run();
    out->set_busy(current != 0);
    out->set_current_run_id(current);
  }
  const hw::AttachedDevices attached = hw::ListAttachedDevices();
  for (const auto& d : attached.devices) {
    auto* a = resp->add_attached();
    a->set_kind(d.kind);
    a->set_vendor_id(d.vendor_id);
    a->set_product_id(d.product_id);
    a->set_serial(d.serial);
    a->set_product(d.product);
    a->set_path(d.path);
  }
  std::string note = attached.note;
  for (const auto& err : attached.errors) note += (note.empty() ? "" : "; ") + err;
  resp->set_attached_note(note);
  return grpc::Status::OK;
}

}  // namespace vb::server
