#include "server/lab.h"

#include <google/protobuf/util/json_util.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <chrono>

#include "db/open_store.h"
#include "runs/execute.h"

namespace vb::server {

namespace {

double NowUnixS() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

constexpr double kWatchPeriod_s = 0.1;     // cancel requests through the store act within this
constexpr int kProgressEveryWatches = 5;   // progress to the store every 0.5 s

}  // namespace

valvebench::v1::BenchInfo DescribeBench(const BenchSetup& b) {
  valvebench::v1::BenchInfo out;
  const bool emulated = b.kind == BenchKind::kEmulated;
  out.set_name(b.name);
  out.set_kind(BenchKindName(b.kind));
  out.set_driver(emulated ? std::string(model::DriverKindName(b.emulated.driver.kind)) : b.caps.driver);
  out.set_model(b.preset);
  out.set_max_supply_v(b.caps.max_supply_V);
  out.set_max_carrier_hz(b.caps.max_carrier_Hz);
  out.set_max_sample_rate_hz(b.caps.max_sample_rate_Hz);
  out.set_max_control_rate_hz(b.caps.max_control_rate_Hz);
  out.set_measures_position(emulated ? b.emulated.plant.has_moving_part : b.caps.measures_position);
  out.set_device(b.device);
  out.set_paced(b.paced);
  out.set_max_current_a(b.safety.max_current_A > 0.0 ? b.safety.max_current_A : b.caps.max_current_A);
  out.set_max_duty(b.safety.max_duty);
  out.set_max_on_time_s(b.safety.max_on_time_s);
  out.set_max_coil_temp_c(b.safety.max_coil_temp_C);
  return out;
}

std::string BenchesJson(const std::vector<BenchSetup>& benches) {
  nlohmann::json a = nlohmann::json::array();
  google::protobuf::util::JsonPrintOptions opt;
  opt.preserve_proto_field_names = true;  // "max_supply_V", as the heartbeats of older builds wrote them
  for (const BenchSetup& b : benches) {
    std::string info;
    (void)google::protobuf::util::MessageToJsonString(DescribeBench(b), &info, opt);
    nlohmann::json entry = nlohmann::json::parse(info);
    entry["bench_class"] = b.bench_class;
    // What admission on another host checks a run against (experiment::CheckCapabilities).
    entry["caps"] = {{"kind", b.caps.kind},
                     {"driver", b.caps.driver},
                     {"max_supply_V", b.caps.max_supply_V},
                     {"min_carrier_Hz", b.caps.min_carrier_Hz},
                     {"max_carrier_Hz", b.caps.max_carrier_Hz},
                     {"max_sample_rate_Hz", b.caps.max_sample_rate_Hz},
                     {"max_control_rate_Hz", b.caps.max_control_rate_Hz},
                     {"measures_position", b.caps.measures_position},
                     {"measures_velocity", b.caps.measures_velocity},
                     {"max_current_A", b.caps.max_current_A},
                     {"device_loops", b.caps.device_loops},
                     {"max_device_loop_Hz", b.caps.max_device_loop_Hz}};
    a.push_back(std::move(entry));
  }
  return a.dump();
}

StatusOr<valvebench::v1::BenchInfo> RegisteredBench(const std::string& bench_json) {
  valvebench::v1::BenchInfo out;
  google::protobuf::util::JsonParseOptions opt;
  opt.ignore_unknown_fields = true;  // bench_class, caps: admission's, not the description's
  if (!google::protobuf::util::JsonStringToMessage(bench_json, &out, opt).ok())
    return Status::InvalidArgument("benches_json: an entry is not a bench description: " + bench_json.substr(0, 200));
  return out;
}

std::vector<BenchSetup> OtherHostsBenches(const std::vector<db::HostRecord>& hosts, const std::string& own_host) {
  std::vector<BenchSetup> out;
  for (const auto& h : hosts) {
    if (h.name == own_host) continue;
    const auto benches = nlohmann::json::parse(h.benches_json, nullptr, false);
    if (!benches.is_array()) continue;
    for (const auto& b : benches) {
      if (!b.is_object() || !b.contains("caps") || !b["caps"].is_object()) continue;  // written by an older build
      const auto& c = b["caps"];
      BenchSetup s;
      s.name = b.value("name", "");
      auto kind = ParseBenchKind(b.value("kind", ""));
      if (!kind.ok()) continue;  // a kind this build does not know: no run can be admitted for it here
      s.kind = *kind;
      s.bench_class = b.value("bench_class", "");
      s.preset = b.value("model", "");
      s.paced = b.value("paced", false);
      s.device = b.value("device", "");
      s.caps.kind = c.value("kind", "");
      s.caps.driver = c.value("driver", "");
      s.caps.max_supply_V = c.value("max_supply_V", 0.0);
      s.caps.min_carrier_Hz = c.value("min_carrier_Hz", 0.0);
      s.caps.max_carrier_Hz = c.value("max_carrier_Hz", 0.0);
      s.caps.max_sample_rate_Hz = c.value("max_sample_rate_Hz", 0.0);
      s.caps.max_control_rate_Hz = c.value("max_control_rate_Hz", 0.0);
      s.caps.measures_position = c.value("measures_position", false);
      s.caps.measures_velocity = c.value("measures_velocity", false);
      s.caps.max_current_A = c.value("max_current_A", 0.0);
      if (c.contains("device_loops") && c["device_loops"].is_array())
        for (const auto& l : c["device_loops"])
          if (l.is_string()) s.caps.device_loops.push_back(l.get<std::string>());
      s.caps.max_device_loop_Hz = c.value("max_device_loop_Hz", 0.0);
      if (!s.name.empty() && !s.bench_class.empty()) out.push_back(std::move(s));
    }
  }
  return out;
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
  for (const auto& w : *workers_) {
    const db::Lease lease = w->executing_lease();
    if (lease.run_id == 0) continue;
    const auto asked = runs::FaultLog::Clock::now();
    auto cancel = store->CancelRequested(lease.run_id);
    if (db::ClassifyWrite(cancel.status()) == db::WriteFault::kTransient) {
      faults_.Failed(cancel.status(), asked);
      return;  // the store is unavailable: the next watch tries again
    }
    if (cancel.ok() && *cancel && w->CancelIfCurrent(lease))
      spdlog::info("run {}: cancel requested through the store: stopping it", static_cast<long long>(lease.run_id));
    if (!write_progress) continue;
    double progress = 0.0;
    if (!registry_->Progress(lease.run_id, &progress)) continue;
    // Under the worker's lock: the run cannot end (and write its result) while its progress is being written.
    db::Lease written;
    const auto writing = runs::FaultLog::Clock::now();
    Status st = w->WithExecutingLease([&](const db::Lease& current) {
      if (current.run_id != lease.run_id || current.fence != lease.fence) return Status::Ok();  // another run now
      written = current;
      return store->SetProgress(current, std::min(1.0, std::max(0.0, progress)));
    });
    switch (db::ClassifyWrite(st)) {
      case db::WriteFault::kNone:
        break;
      case db::WriteFault::kTransient:  // progress is only for watchers: the next one is 0.5 s away
        faults_.Failed(st, writing);
        return;
      case db::WriteFault::kFenced:
        spdlog::warn("run {} (fence {}): {}; stopping this attempt", static_cast<long long>(written.run_id),
                     static_cast<long long>(written.fence), st.message());
        w->CancelIfCurrent(written);
        break;
      case db::WriteFault::kPermanent:
        spdlog::error("run {}: cannot write its progress: {}", static_cast<long long>(written.run_id), st.message());
        break;
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
