#include "server/lab.h"

#include <google/protobuf/util/json_util.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <chrono>

#include "db/open_store.h"
#include "runs/execute.h"
#include "runs/watch.h"

namespace vb::server {

namespace {

double NowUnixS() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

constexpr double kWatchPeriod_s = 0.1;     // cancel requests through the store act within this
constexpr int kProgressEveryWatches = 5;   // progress to the store every 0.5 s

}  // namespace

LabHost::LabHost(LabSetup setup, std::string db_path, std::string benches_json, runs::Registry* registry,
                 const std::vector<std::unique_ptr<runs::Worker>>* workers)
    : setup_(std::move(setup)),
      db_path_(std::move(db_path)),
      benches_json_(std::move(benches_json)),
      started_unix_s_(NowUnixS()),
      registry_(registry),
      workers_(workers),
      stop_([] { return NowUnixS(); }) {}

LabHost::~LabHost() { Stop(); }

Status LabHost::Beat(db::Store* store) {
  db::HostRecord me;
  me.name = setup_.host;
  me.address = setup_.advertised_address;
  // Each bench's fault, as it is now (the rest of the description does not change).
  auto benches = nlohmann::json::parse(benches_json_, nullptr, false);
  if (benches.is_array() && workers_ != nullptr)
    for (auto& b : benches)
      for (const auto& w : *workers_)
        if (b.is_object() && w->setup().name == b.value("name", "")) b["fault"] = w->fault();
  me.benches_json = benches.is_array() ? benches.dump() : benches_json_;
  me.started_unix_s = started_unix_s_;
  // Only the runs whose experiments are executing here: a run that ended and whose result is not written yet
  // is not kept alive (issue 30).
  std::vector<db::Lease> executing;
  if (workers_ != nullptr)
    for (const auto& w : *workers_)
      if (const db::Lease lease = w->executing_lease(); lease.run_id != 0) executing.push_back(lease);
  // And the runs whose trace or result the host's spool is still uploading: their host is alive and holds them
  // (runs/spool.h); they lapse only if this host stops heartbeating.
  if (spool_ != nullptr)
    for (const db::Lease& lease : spool_->Uploading()) executing.push_back(lease);
  VB_RETURN_IF_ERROR(store->Heartbeat(me, setup_.lease_ttl_s, executing));
  const auto now = std::chrono::steady_clock::now();
  if (faults_.in_fault()) {
    // The store is back after a fault: every host's leases may have lapsed meanwhile. Re-queueing now would
    // take the runs of hosts that simply have not had their first heartbeat since; give them one lease TTL.
    reap_after_ = now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(setup_.lease_ttl_s));
  }
  faults_.Recovered();
  if (now < reap_after_) return Status::Ok();
  auto lapsed = store->RequeueLapsed();
  if (!lapsed.ok()) return lapsed.status();
  if (!lapsed->empty()) {
    std::string ids;
    for (auto id : *lapsed) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
    spdlog::warn("lab: {} run(s) whose host stopped renewing their lease re-queued: {}", lapsed->size(), ids);
    registry_->NotifyWork();
  }
  return Status::Ok();
}

Status LabHost::Start() {
  auto store = db::OpenStore(db_path_);
  if (!store.ok()) return store.status();
  store_ = std::move(store).value();
  VB_RETURN_IF_ERROR(Beat(store_.get()).WithContext("lab: first heartbeat of host " + setup_.host));
  faults_.Recovered();
  thread_ = std::thread([this] { Loop(); });
  return Status::Ok();
}

void LabHost::Stop() {
  stop_.Stop();
  if (thread_.joinable()) thread_.join();
}

void LabHost::WatchRuns(db::Store* store, bool write_progress) {
  runs::WatchRuns(store, *workers_, registry_, write_progress, &faults_);
}

void LabHost::Loop() {
  using Clock = std::chrono::steady_clock;
  auto next_beat = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(setup_.heartbeat_s));
  int watches = 0;
  while (stop_.SleepFor(kWatchPeriod_s)) {
    if (Clock::now() >= next_beat) {
      // Scheduled from the previous target, not from now: a slow heartbeat does not push the next one later.
      next_beat += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(setup_.heartbeat_s));
      if (next_beat < Clock::now()) next_beat = Clock::now();
      const auto beat_began = runs::FaultLog::Clock::now();
      if (Status st = Beat(store_.get()); db::ClassifyWrite(st) == db::WriteFault::kTransient) {
        faults_.Failed(st, beat_began);  // logged once when the fault begins, and with its duration when it ends
      } else if (!st.ok()) {
        spdlog::error("lab: heartbeat failed: {}", st.message());
      }
    }
    WatchRuns(store_.get(), ++watches % kProgressEveryWatches == 0);
  }
}

}  // namespace vb::server
