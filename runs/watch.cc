#include "runs/watch.h"

#include <spdlog/spdlog.h>

#include <algorithm>

namespace vb::runs {

void WatchRuns(db::Store* store, const std::vector<std::unique_ptr<Worker>>& workers, Registry* registry,
               bool write_progress, FaultLog* faults) {
  for (const auto& w : workers) {
    const db::Lease lease = w->executing_lease();
    if (lease.run_id == 0) continue;
    const auto asked = FaultLog::Clock::now();
    auto cancel = store->CancelRequested(lease.run_id);
    if (db::ClassifyWrite(cancel.status()) == db::WriteFault::kTransient) {
      faults->Failed(cancel.status(), asked);
      return;  // the store is unavailable: the next watch tries again
    }
    if (cancel.ok() && *cancel && w->CancelIfCurrent(lease))
      spdlog::info("run {}: cancel requested through the store: stopping it", static_cast<long long>(lease.run_id));
    if (!write_progress) continue;
    double progress = 0.0;
    if (registry == nullptr || !registry->Progress(lease.run_id, &progress)) continue;
    // Under the worker's lock: the run cannot end (and write its result) while its progress is being written.
    db::Lease written;
    const auto writing = FaultLog::Clock::now();
    Status st = w->WithExecutingLease([&](const db::Lease& current) {
      if (current.run_id != lease.run_id || current.fence != lease.fence) return Status::Ok();  // another run now
      written = current;
      return store->SetProgress(current, std::min(1.0, std::max(0.0, progress)));
    });
    switch (db::ClassifyWrite(st)) {
      case db::WriteFault::kNone:
        break;
      case db::WriteFault::kTransient:  // progress is only for watchers: the next write is a moment away
        faults->Failed(st, writing);
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

}  // namespace vb::runs
