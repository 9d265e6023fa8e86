#include "benchctl/local_run.h"

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <memory>
#include <mutex>
#include <thread>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>

#include "common/csv.h"
#include "db/open_store.h"
#include "db/store.h"
#include "runs/admit.h"
#include "runs/worker.h"

namespace vb::benchctl {

std::string DefaultLocalStorePath() {
  if (const char* p = std::getenv("VALVEBENCH_DB"); p != nullptr && *p != '\0') return p;
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0')
    return std::string(home) + "/.local/share/valvebench/local.db";
  return "valvebench-local.db";
}

namespace {

constexpr const char* kLeftOverReason = "left over from an interrupted local run";

// Runs of the local bench still queued from an invocation that was interrupted before it ran them.
Status CancelLeftOvers(db::Store* store, const std::string& bench_class) {
  db::RunFilter f;
  f.status = db::RunStatus::kQueued;
  f.limit = 1000;
  for (;;) {
    auto page = store->ListRuns(f);
    if (!page.ok()) return page.status();
    for (const auto& r : *page)
      if (r.bench_kind == bench_class) VB_RETURN_IF_ERROR(store->RequestCancel(r.id, kLeftOverReason).status());
    if (static_cast<int>(page->size()) < f.limit) return Status::Ok();
    f.after_id = page->back().id;
  }
}

// Another benchctl (watch, cancel, queue) sees local runs only through the store file: while a run executes,
// this thread copies the loop's progress (by simulated time, runs::Registry) into the store and a cancel
// request found in the store into the loop: the cancel every 20 ms (a cancel lands within 100 ms of wall time,
// docs/server.md "Cancel"), the progress every 200 ms (a write). It has its own connection to the file.
class StoreRelay {
 public:
  StoreRelay(const std::string& path, runs::Registry* registry, const runs::Worker* worker)
      : registry_(registry), worker_(worker) {
    auto s = db::OpenStore(path);
    if (!s.ok()) return;  // nobody else can watch then; the runs themselves are unaffected
    store_ = std::move(s.value());
    thread_ = std::thread([this] { Loop(); });
  }
  ~StoreRelay() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  StoreRelay(const StoreRelay&) = delete;
  StoreRelay& operator=(const StoreRelay&) = delete;

 private:
  void Loop() {
    std::unique_lock<std::mutex> lock(mu_);
    while (!cv_.wait_for(lock, std::chrono::milliseconds(20), [this] { return stop_; })) {
      const std::int64_t id = worker_->current_run();
      if (id == 0) continue;
      double progress = 0.0;
      if (++ticks_ % 10 == 0 && registry_->Progress(id, &progress))
        (void)store_->SetProgress(worker_->current_lease(), progress);
      if (auto c = store_->CancelRequested(id); c.ok() && *c) registry_->Cancel(id);
    }
  }

  runs::Registry* registry_;
  const runs::Worker* worker_;
  std::unique_ptr<db::Store> store_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::uint64_t ticks_ = 0;
  std::thread thread_;
};

}  // namespace

StatusOr<std::vector<LocalRunResult>> RunLocal(LocalSubmission sub, db::Store* given) {
  const runs::BenchSetup bench = runs::LocalEmulatorSetup();
  runs::Policy policy;
  policy.benches = {bench};
  policy.limits.max_trace_bytes_per_run = runs::LocalTraceBudgetBytes();
  if (sub.realtime)
    for (auto& s : sub.specs) s.set_realtime(true);
  const char* user = std::getenv("USER");
  const std::string submitter = user != nullptr && *user != '\0' ? user : "local";
  auto admitted = runs::Admit({submitter, sub.batch_name, std::move(sub.specs), std::move(sub.keys), sub.batch_json}, policy);
  if (!admitted.ok()) return admitted.status();

  const bool stored = !sub.store_path.empty();
  const std::string where = stored ? "local store " + db::DisplayLocation(sub.store_path) : "in-memory store";
  std::unique_ptr<db::Store> opened;
  db::Store* store = given;
  if (store == nullptr) {
    if (stored && !db::IsPostgresLocation(sub.store_path)) {
      if (const auto parent = std::filesystem::path(sub.store_path).parent_path(); !parent.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(parent, ec);
      }
    }
    auto s = db::OpenStore(stored ? sub.store_path : ":memory:");
    if (!s.ok()) return s.status().WithContext(where);
    opened = std::move(s.value());
    store = opened.get();
  }
  VB_RETURN_IF_ERROR(CancelLeftOvers(store, bench.bench_class).WithContext(where));

  std::map<std::int64_t, LocalRunResult> pending;
  std::vector<LocalRunResult> shapes;
  for (const auto& r : admitted->runs) shapes.push_back({0, 0, r.key, r.tags, r.controller, {}, {}});
  auto queued = runs::Enqueue(store, std::move(admitted.value()), policy);
  if (!queued.ok()) return queued.status().WithContext(where);
  for (size_t k = 0; k < queued->run_ids.size(); ++k) pending[queued->run_ids[k]] = std::move(shapes[k]);

  runs::Registry registry;
  runs::Worker worker(bench, stored ? &registry : nullptr);
  worker.set_keep_traces(sub.keep_traces);
  std::unique_ptr<StoreRelay> relay;
  if (stored) relay = std::make_unique<StoreRelay>(sub.store_path, &registry, &worker);
  std::vector<LocalRunResult> out;
  while (!pending.empty()) {
    auto done = worker.ClaimAndExecute(store);
    if (!done.ok()) return done.status().WithContext(where);
    if (!done->has_value()) {
      // Nothing left to claim: the rest of the batch was cancelled while queued (benchctl cancel from another
      // shell). They are results too, with the state they reached.
      for (auto& [id, r] : pending) {
        auto row = store->GetRun(id);
        if (!row.ok()) return row.status().WithContext(where);
        if (row->status == RunStatus::kQueued)
          return Status::Internal(where + ": run " + std::to_string(id) + " is queued but was not there to claim");
        r.run_id = stored || given != nullptr ? id : 0;
        r.batch_id = stored || given != nullptr ? queued->batch_id : 0;
        r.summary.termination = row->status == RunStatus::kCancelled ? experiment::RunSummary::Termination::kCancelled
                                                                     : experiment::RunSummary::Termination::kFailed;
        r.summary.message = row->reason;
        out.push_back(std::move(r));
      }
      break;
    }
    runs::Outcome& o = **done;
    auto it = pending.find(o.run_id);
    if (it == pending.end()) return Status::Internal(where + ": claimed run " + std::to_string(o.run_id) + ", not ours");
    if (!o.recorded) return Status::Unavailable(where + ": cannot record run " + std::to_string(o.run_id));
    LocalRunResult r = std::move(it->second);
    pending.erase(it);
    r.run_id = stored || given != nullptr ? o.run_id : 0;
    r.batch_id = stored || given != nullptr ? queued->batch_id : 0;
    r.summary = std::move(o.summary);
    if (sub.keep_traces) r.trace = std::move(o.trace);
    out.push_back(std::move(r));
  }
  return out;
}

Status WriteTraceCsv(const experiment::Trace& trace, const std::string& path) {
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) return Status::Unavailable(path + ": cannot open for writing");
  const auto& names = experiment::Trace::ChannelNames();
  for (size_t c = 0; c < names.size(); ++c) std::fprintf(f.get(), "%s%s", c ? "," : "", names[c].c_str());
  std::fputc('\n', f.get());
  for (size_t k = 0; k < trace.size(); ++k) {
    // ref is NaN for a law without a reference: an empty field (common/csv.h AppendCsvNumber).
    std::fprintf(f.get(), "%.8f,%d,%.6g,%.9g,%.9g,%.9g,%s,%.9g,%.9g,%.12g,%.12g,%.0f\n", trace.t_s[k],
                 trace.gate[k], trace.v_coil_V[k], trace.i_A[k], trace.x_m[k], trace.v_mps[k], CsvNumber(trace.ref[k], 9).c_str(),
                 trace.x_avg_m[k], trace.flow_kg_per_s[k], trace.v2_int_V2s[k], trace.energy_int_J[k],
                 trace.switch_count[k]);
  }
  if (std::ferror(f.get())) return Status::DataLoss(path + ": write failed");
  return Status::Ok();
}

}  // namespace vb::benchctl
