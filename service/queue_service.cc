// BenchServiceImpl::GetQueue: the running runs and the queue in claim order, each with its position and ETA
// (common/queue_estimate.h, docs/lab.md "The queue"), over the benches ListBenches reports. The one queue view
// every client shows (benchctl queue, the web page's queue), computed once here instead of in each client.
#include <algorithm>
#include <chrono>
#include <map>
#include <set>

#include "common/bench_kind.h"
#include "common/queue_estimate.h"
#include "runs/worker.h"
#include "service/grpc_status.h"
#include "service/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

constexpr std::int32_t kPage = 1000;
constexpr std::size_t kMaxRuns = 100000;  // a queue longer than this is cut (the estimate covers what is read)

// Which runs a bench claims (db::BenchClaim: its class and name): this server's workers know their class; a lab's
// other benches are described by kind and model, the class's parts (common/bench_kind.h).
QueueBench ClaimerOf(const v1::BenchInfo& b, bool live, const std::vector<std::unique_ptr<runs::Worker>>& workers) {
  QueueBench q;
  q.name = b.name();
  q.live = live;
  if (b.host().empty()) {
    for (const auto& w : workers) {
      if (w->setup().name != b.name()) continue;
      q.bench_class = w->setup().bench_class;
      return q;
    }
  }
  auto kind = ParseBenchKind(b.kind());
  q.bench_class = kind.ok() ? BenchClass(*kind, b.model()) : b.kind();
  return q;
}

}  // namespace

grpc::Status BenchServiceImpl::GetQueue(grpc::ServerContext* ctx, const v1::GetQueueRequest* /*req*/,
                                        v1::GetQueueResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  // The benches first: a run that starts between the two reads is then counted running, not missed.
  const v1::ListBenchesRequest benches_req;
  v1::ListBenchesResponse benches;
  if (auto st = ListBenches(ctx, &benches_req, &benches); !st.ok()) return st;
  int live = 0;
  std::vector<QueueBench> claimers;
  for (auto& b : *benches.mutable_benches()) {
    const bool alive = b.host().empty() || b.alive();
    live += alive;
    claimers.push_back(ClaimerOf(b, alive, *workers_));
    *resp->add_benches() = std::move(b);
  }
  resp->set_live_benches(live);

  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  std::vector<v1::Run> running, queued;
  std::map<std::int64_t, std::pair<std::string, std::string>> claim_of;  // run id -> (class, bench name)
  for (db::RunStatus status : {db::RunStatus::kRunning, db::RunStatus::kQueued}) {
    auto& list = status == db::RunStatus::kRunning ? running : queued;
    std::set<std::int64_t> seen;
    db::RunFilter f;
    f.status = status;
    f.limit = kPage;
    for (;;) {
      auto page = (*store)->ListRuns(f);
      if (!page.ok()) return ToGrpcStatus(page.status());
      std::int64_t last = f.after_id;
      for (const auto& r : *page) {
        last = std::max(last, r.id);
        if (!seen.insert(r.id).second) continue;
        v1::Run run;
        if (auto st = FillRun(store->get(), r, false, &run); !st.ok()) return st;
        claim_of[r.id] = {r.bench_kind, r.bench_name};
        list.push_back(std::move(run));
      }
      if (static_cast<std::int32_t>(page->size()) < f.limit || last == f.after_id || list.size() >= kMaxRuns) break;
      f.after_id = last;
    }
  }

  auto info = [&](const v1::Run& r, RunStatus status) {
    const auto& [cls, name] = claim_of[r.id()];
    return QueueRunInfo{r.id(),  status, r.priority(), r.duration_s(), r.progress(), r.started_unix_s(),
                        cls,     name};
  };
  std::vector<QueueRunInfo> all;
  for (const auto& r : running) all.push_back(info(r, RunStatus::kRunning));
  for (const auto& r : queued) all.push_back(info(r, RunStatus::kQueued));
  const auto estimates = EstimateQueue(all, claimers);
  const double now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  resp->set_at_unix_s(now);
  std::sort(running.begin(), running.end(), [](const v1::Run& a, const v1::Run& b) { return a.id() < b.id(); });
  for (auto& r : running) {
    auto* q = resp->add_running();
    q->set_position(0);
    q->set_eta_s(RunningEta_s(info(r, RunStatus::kRunning), now));
    *q->mutable_run() = std::move(r);
  }
  std::stable_sort(queued.begin(), queued.end(), [&](const v1::Run& a, const v1::Run& b) {
    return estimates.at(a.id()).position < estimates.at(b.id()).position;
  });
  for (auto& r : queued) {
    const QueueEstimate& e = estimates.at(r.id());
    auto* q = resp->add_queued();
    q->set_position(e.position);
    q->set_eta_s(e.eta_s);
    *q->mutable_run() = std::move(r);
  }
  return grpc::Status::OK;
}

}  // namespace vb::server
