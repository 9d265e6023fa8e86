#include "server/lab.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <chrono>

#include "runs/execute.h"

namespace vb::server {

namespace {

double NowUnixS() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

constexpr double kWatchPeriod_s = 0.1;     // cancel requests through the store act within this
constexpr int kProgressEveryWatches = 5;   // progress to the store every 0.5 s

}  // namespace

std::string BenchesJson(const std::vector<BenchSetup>& benches) {
  nlohmann::json a = nlohmann::json::array();
  for (const BenchSetup& b : benches) {
    a.push_back({{"name", b.name},
                 {"kind", b.kind},
                 {"bench_class", b.bench_class},
                 {"model", b.preset},
                 {"driver", b.kind == "emulated" ? std::string(model::DriverKindName(b.emulated.driver.kind))
                                                 : b.caps.driver},
                 {"paced", b.paced},
                 {"device", b.device},
                 {"max_supply_V", b.caps.max_supply_V},
                 {"max_carrier_Hz", b.caps.max_carrier_Hz},
                 {"max_sample_rate_Hz", b.caps.max_sample_rate_Hz},
                 {"max_control_rate_Hz", b.caps.max_control_rate_Hz},
                 {"measures_position",
                  b.kind == "emulated" ? b.emulated.plant.has_moving_part : b.caps.measures_position}});
  }
  return a.dump();
}

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
  me.benches_json = benches_json_;
  me.started_unix_s = started_unix_s_;
  VB_RETURN_IF_ERROR(store->Heartbeat(me, setup_.lease_ttl_s));
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
  auto store = db::Store::Open(db_path_);
  if (!store.ok()) return store.status();
  store_ = std::move(store).value();
  VB_RETURN_IF_ERROR(Beat(store_.get()).WithContext("lab: first heartbeat of host " + setup_.host));
  thread_ = std::thread([this] { Loop(); });
  return Status::Ok();
}

void LabHost::Stop() {
  stop_.Stop();
  if (thread_.joinable()) thread_.join();
}

void LabHost::WatchRuns(db::Store* store, bool write_progress) {
  for (const auto& w : *workers_) {
    const db::Lease lease = w->current_lease();
    if (lease.run_id == 0) continue;
    auto cancel = store->CancelRequested(lease.run_id);
    if (cancel.ok() && *cancel && w->CancelIfCurrent(lease))
      spdlog::info("run {}: cancel requested through the store: stopping it", static_cast<long long>(lease.run_id));
    if (!write_progress) continue;
    double progress = 0.0;
    if (!registry_->Progress(lease.run_id, &progress)) continue;
    Status st = store->SetProgress(lease, std::min(1.0, std::max(0.0, progress)));
    if (runs::IsStaleWrite(st)) {
      spdlog::warn("run {} (fence {}): {}; stopping this attempt", static_cast<long long>(lease.run_id),
                   static_cast<long long>(lease.fence), st.message());
      w->CancelIfCurrent(lease);
    }
  }
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
      if (Status st = Beat(store_.get()); !st.ok()) spdlog::error("lab: heartbeat failed: {}", st.message());
    }
    WatchRuns(store_.get(), ++watches % kProgressEveryWatches == 0);
  }
}

}  // namespace vb::server
