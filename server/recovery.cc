#include "server/recovery.h"

#include <spdlog/spdlog.h>

#include "db/open_store.h"

namespace vb::server {

StatusOr<Recovery> RecoverAtStart(const Settings& settings, const std::string& host, db::Store* store) {
  Recovery out;
  if (!settings.spool_dir.empty()) {
    runs::SpoolOptions options;
    options.dir = settings.spool_dir;
    options.max_bytes = settings.spool_max_bytes;
    const std::string db_path = settings.database_path;
    out.spool = std::make_unique<runs::Spool>(options, [db_path] { return db::OpenStore(db_path); });
    VB_RETURN_IF_ERROR(out.spool->Open());
    runs::RetryPolicy retry;
    retry.give_up_s = 60.0;
    runs::FaultLog faults("spool");
    auto left = out.spool->DrainLeftovers(store, retry, &faults);
    if (!left.ok()) return left.status();
    out.stopped_unix_s = left->stopped_unix_s;
    if (left->results_landed + left->stale + left->dropped > 0)
      spdlog::info("spool {}: {} result(s) left by the last process uploaded, {} no longer its runs', {} attempt(s) "
                   "without a result dropped", settings.spool_dir, left->results_landed, left->stale, left->dropped);
  } else {
    spdlog::warn("no spool_dir: runs' traces and results go to the database directly (the trace stream waits for "
                 "it; docs/lab.md, \"The spool\")");
  }
  auto recovered = store->RecoverAfterCrashAt(host, out.stopped_unix_s);
  if (!recovered.ok()) return recovered.status().WithContext("recovery failed");
  out.interrupted = *recovered;
  return out;
}

}  // namespace vb::server
