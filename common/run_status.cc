#include "common/run_status.h"

namespace vb {

const char* RunStatusName(RunStatus s) {
  switch (s) {
    case RunStatus::kQueued: return "queued";
    case RunStatus::kRunning: return "running";
    case RunStatus::kDone: return "done";
    case RunStatus::kFailed: return "failed";
    case RunStatus::kCancelled: return "cancelled";
    case RunStatus::kInterrupted: return "interrupted";
  }
  return "unknown";
}

StatusOr<RunStatus> ParseRunStatus(const std::string& name) {
  for (RunStatus s : {RunStatus::kQueued, RunStatus::kRunning, RunStatus::kDone, RunStatus::kFailed,
                      RunStatus::kCancelled, RunStatus::kInterrupted}) {
    if (name == RunStatusName(s)) return s;
  }
  return Status::InvalidArgument("unknown run status \"" + name +
                                 "\" (expected queued, running, done, failed, cancelled or interrupted)");
}

bool Ended(RunStatus s) { return s == RunStatus::kDone || s == RunStatus::kFailed || s == RunStatus::kCancelled; }

}  // namespace vb
