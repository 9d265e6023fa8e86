#include "service/host.h"

#include <spdlog/spdlog.h>

#include <chrono>

#include "db/open_store.h"
#include "runs/watch.h"
#include "service/hosting.h"

namespace vb::server {

namespace {

constexpr const char* kLeftOverReason = "left over from an interrupted local run";

// Runs of these benches still queued from an invocation that was interrupted before it ran them.
Status CancelLeftOvers(db::Store* store, const std::vector<runs::BenchSetup>& benches) {
  db::RunFilter f;
  f.status = db::RunStatus::kQueued;
  f.limit = 1000;
  for (;;) {
    auto page = store->ListRuns(f);
    if (!page.ok()) return page.status();
    for (const auto& r : *page)
      for (const auto& b : benches)
        if (r.bench_kind == b.bench_class) {
          VB_RETURN_IF_ERROR(store->RequestCancel(r.id, kLeftOverReason).status());
          break;
        }
    if (static_cast<int>(page->size()) < f.limit) return Status::Ok();
    f.after_id = page->back().id;
  }
}

}  // namespace

StatusOr<std::unique_ptr<Host>> Host::Start(HostOptions options, grpc::ServerBuilder* builder) {
  if (options.settings == nullptr) return Status::Internal("Host::Start: no settings");
  std::unique_ptr<Host> h(new Host(std::move(options)));
  VB_RETURN_IF_ERROR(h->Init(builder));
  return h;
}

Status Host::Recover(db::Store* store) {
  const ServiceSettings& s = *options_.settings;
  if (options_.recovery == HostOptions::Recovery::kNone) return Status::Ok();
  if (options_.recovery == HostOptions::Recovery::kCancelLeftOvers) return CancelLeftOvers(store, s.benches);
  // In a lab only this host's runs: the others' are running on their hosts (docs/lab.md).
  const std::string host = s.lab.enabled ? s.lab.host : std::string();
  double stopped_unix_s = 0.0;
  if (!options_.spool_dir.empty()) {
    runs::SpoolOptions spool;
    spool.dir = options_.spool_dir;
    spool.max_bytes = options_.spool_max_bytes;
    spool_ = std::make_unique<runs::Spool>(spool, [path = options_.store] { return db::OpenStore(path); });
    VB_RETURN_IF_ERROR(spool_->Open());
    runs::RetryPolicy retry;
    retry.give_up_s = 60.0;
    runs::FaultLog faults("spool");
    auto left = spool_->DrainLeftovers(store, retry, &faults);
    if (!left.ok()) return left.status();
    stopped_unix_s = left->stopped_unix_s;
    if (left->results_landed + left->stale + left->dropped > 0)
      spdlog::info("spool {}: {} result(s) left by the last process uploaded, {} no longer its runs', {} attempt(s) "
                   "without a result dropped", options_.spool_dir, left->results_landed, left->stale, left->dropped);
    spool_->set_registry(&registry_);
  } else {
    spdlog::warn("no spool_dir: runs' traces and results go to the database directly (the trace stream waits for "
                 "it; docs/lab.md, \"The spool\")");
  }
  auto recovered = store->RecoverAfterCrashAt(host, stopped_unix_s);
  if (!recovered.ok()) return recovered.status().WithContext("recovery failed");
  interrupted_ = *recovered;
  return Status::Ok();
}

Status Host::Init(grpc::ServerBuilder* builder) {
  const ServiceSettings& s = *options_.settings;
  // 1-2. The store and the recovery, on one connection of the pool (the first opens and migrates the store).
  pool_ = std::make_unique<StorePool>(options_.store);
  {
    auto store = pool_->Acquire();
    if (!store.ok()) return store.status();
    VB_RETURN_IF_ERROR(Recover(store->get()));
  }
  // 3. The workers.
  for (const auto& b : s.benches) {
    workers_.push_back(std::make_unique<runs::Worker>(b, &registry_));
    runs::Worker& w = *workers_.back();
    w.set_spool(spool_.get());
    w.set_keep_traces(options_.keep_traces);
    if (s.lab.enabled) w.set_claim_policy({s.lab.host, s.lab.lease_ttl_s, s.lab.aging_s});
    if (options_.on_outcome) w.set_on_outcome(options_.on_outcome);
  }
  // 4. The service on the builder.
  service_ = std::make_unique<BenchServiceImpl>(&s, pool_.get(), &registry_, &workers_);
  HostService(builder, service_.get());
  server_ = builder->BuildAndStart();
  if (server_ == nullptr) return Status::Unavailable("the gRPC server did not start");
  return Status::Ok();
}

void Host::Run() {
  if (spool_) spool_->Start();
  for (auto& w : workers_) w->Start(options_.store);
  if (options_.watch_period_s > 0.0) relay_ = std::thread([this] { RelayLoop(); });
}

// Another process on the same store sees this host's runs only through it: runs::WatchRuns relays a cancel
// requested there, the progress, and stops an attempt whose lease another one took.
void Host::RelayLoop() {
  std::unique_ptr<db::Store> store;
  const auto period = std::chrono::duration<double>(options_.watch_period_s);
  for (std::uint64_t tick = 0; !relay_stop_.load(); ++tick) {
    std::this_thread::sleep_for(period);
    if (store == nullptr) {
      const auto began = runs::FaultLog::Clock::now();
      auto opened = db::OpenStore(options_.store);
      if (!opened.ok()) {  // nobody else can watch then; the runs themselves are unaffected
        relay_faults_.Failed(opened.status(), began);
        continue;
      }
      store = std::move(opened).value();
    }
    runs::WatchRuns(store.get(), workers_, &registry_, tick % options_.progress_every == 0, &relay_faults_);
  }
}

void Host::StopBenches(StopMode mode) {
  for (auto& w : workers_) {
    if (mode == StopMode::kCancel) {
      w->StopCancelling();
    } else {
      w->Stop();
    }
  }
  benches_stopped_ = true;
}

void Host::StopRest() {
  if (rest_stopped_) return;
  rest_stopped_ = true;
  relay_stop_.store(true);
  if (relay_.joinable()) relay_.join();
  if (spool_) spool_->Stop();  // after the workers: what it has not uploaded stays on disk for the next start
}

Host::~Host() {
  if (!benches_stopped_) StopBenches(StopMode::kLeaveRunning);
  StopRest();
  if (server_) server_->Shutdown(std::chrono::system_clock::now());
  server_.reset();
  service_.reset();
  workers_.clear();
  pool_.reset();
}

}  // namespace vb::server
