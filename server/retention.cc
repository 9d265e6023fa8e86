#include "server/retention.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <spdlog/spdlog.h>

#include "common/format.h"
#include "regress/cron.h"

namespace vb::server {

namespace {

constexpr double kDay_s = 86400.0;

double WallClock() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

}  // namespace

StatusOr<db::PruneResult> PruneWithServerRules(StorePool* pool, const NightsSetup& nights, db::PruneRequest req) {
  if (!nights.baseline_path.empty()) {
    auto b = LoadBaselineFile(nights.baseline_path);
    if (!b.ok()) {
      // Without the file nobody can tell which batch it came from: refuse rather than risk deleting it.
      return Status::FailedPrecondition("nights.baseline_file " + nights.baseline_path +
                                        " cannot be read, so the runs it references cannot be protected: " +
                                        b.status().message());
    }
    if (const std::int64_t batch = db::ServerBatchOfBaselineSource(b->source); batch > 0) {
      req.protected_batches.push_back(batch);
      req.protected_why = "the nights' baseline file (" + b->name + ", source \"" + b->source + "\")";
    }
  }
  auto store = pool->Acquire();
  if (!store.ok()) return store.status();
  return (*store)->Prune(req);
}

RetentionScheduler::RetentionScheduler(RetentionSetup setup, NightsSetup nights, StorePool* pool, ClockFn clock)
    : setup_(std::move(setup)),
      nights_(std::move(nights)),
      pool_(pool),
      clock_(clock ? std::move(clock) : WallClock) {}

RetentionScheduler::~RetentionScheduler() { Stop(); }

void RetentionScheduler::Start() {
  thread_ = std::thread([this] { Loop(); });
}

void RetentionScheduler::Stop() {
  stop_signal_.Stop();
  if (thread_.joinable()) thread_.join();
}

void RetentionScheduler::Loop() {
  auto cron = regress::Cron::Parse(setup_.cron);
  if (!cron.ok()) {  // validated with the config; kept as a guard
    spdlog::error("retention.cron: {}; nothing will be pruned", cron.status().message().c_str());
    return;
  }
  for (;;) {
    auto next = cron->NextUnix(clock_(), /*utc=*/true);
    if (!next.ok()) {
      spdlog::error("retention.cron '{}': {}; nothing will be pruned", setup_.cron.c_str(),
                    next.status().message().c_str());
      return;
    }
    if (!stop_signal_.SleepUntil(*next)) return;
    auto r = RunOnce(*next);
    if (!r.ok()) spdlog::error("retention: {}; nothing deleted", r.status().message().c_str());
  }
}

StatusOr<db::PruneResult> RetentionScheduler::RunOnce(double fire_unix_s) {
  db::PruneRequest req;
  req.finished_before_unix_s = fire_unix_s - setup_.older_than_days * kDay_s;
  req.keep_last = setup_.keep_last;
  if (!std::isfinite(req.finished_before_unix_s) || req.finished_before_unix_s <= 0)
    return Status::InvalidArgument("retention.older_than_days: reaches before 1970");
  auto r = PruneWithServerRules(pool_, nights_, req);
  if (!r.ok()) return r.status();
  spdlog::info("retention: deleted {} run(s) that finished before {} ({} trace bytes, {} empty batch(es)); kept {} "
               "old or unfinished run(s) (protected or queued/running/interrupted; reasons at debug level) and {} "
               "newer run(s)",
               r->deleted.size(), FormatUtc(req.finished_before_unix_s).c_str(), static_cast<long long>(r->trace_bytes),
               static_cast<long long>(r->batches_deleted), r->kept.size(), static_cast<long long>(r->newer_kept));
  for (const auto& d : r->deleted)
    spdlog::debug("retention: deleted run {} (batch {}) {}: {}", static_cast<long long>(d.run_id),
                  static_cast<long long>(d.batch_id), d.name.c_str(), d.why.c_str());
  for (const auto& d : r->kept)
    spdlog::debug("retention: kept run {} (batch {}) {}: {}", static_cast<long long>(d.run_id),
                  static_cast<long long>(d.batch_id), d.name.c_str(), d.why.c_str());
  return r;
}

}  // namespace vb::server
