#include "db/run_rules.h"

namespace vb::db::rules {

std::string LapsedReason(const std::string& host) {
  return Cat("lease lapsed: host ", host.empty() ? std::string("(none)") : host, " stopped renewing it");
}

AfterInterrupt AfterInterruption(bool cancel_requested, const std::string& cancel_reason, bool requeue,
                                 std::int64_t interruptions, const std::string& interrupt_reason) {
  if (cancel_requested) {
    // Somebody asked to cancel it while it ran: it has stopped now, so the request is fulfilled.
    return {RunStatus::kCancelled,
            cancel_reason.empty() ? std::string("cancel requested before the server restarted") : cancel_reason};
  }
  if (!requeue) return {RunStatus::kInterrupted, interrupt_reason};
  if (interruptions >= kMaxInterruptions) {
    return {RunStatus::kFailed, Cat("the server stopped ", interruptions,
                                    " times while this run ran: not re-queued again (a run that takes the server "
                                    "down; see the server's log)")};
  }
  return {RunStatus::kQueued, interrupt_reason};
}

std::optional<std::string> StaleWriteWhy(const Lease& lease, const std::string& what, RunStatus status,
                                         std::int64_t fence, const std::string& host) {
  const bool running = status == RunStatus::kRunning;
  if (running && fence == lease.fence) return std::nullopt;
  const std::string holder = !running ? std::string("nobody") : host.empty() ? "another attempt" : "host " + host;
  return Cat("stale write: ", what, " for run ", lease.run_id, " with fence ", lease.fence, " refused: the run is ",
             RunStatusName(status), (running ? "" : ", not running"), ", its fence is ", fence, " (held by ", holder,
             "); the run is no longer this attempt's");
}

Status RunNotFound(std::int64_t id) { return Status::NotFound(Cat("run ", id, " not found")); }

StatusOr<RunStatus> StoredStatus(const std::string& text, std::string_view what) {
  StatusOr<RunStatus> s = ParseRunStatus(text);
  if (!s.ok()) return Status::DataLoss(Cat(what, ": ", s.status().message()));
  return s;
}

}  // namespace vb::db::rules
