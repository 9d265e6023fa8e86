// The one run-status vocabulary: the store's column, the API enum (proto/api_convert.h maps it), what
// benchctl prints and what the run pipeline records. Names are lower case: "queued", "running", "done",
// "failed", "cancelled", "interrupted".
#pragma once

#include <string>

#include "common/status.h"

namespace vb {

enum class RunStatus { kQueued, kRunning, kDone, kFailed, kCancelled, kInterrupted };

const char* RunStatusName(RunStatus s);
// InvalidArgument listing the names when `name` is none of them.
StatusOr<RunStatus> ParseRunStatus(const std::string& name);
// Done, failed or cancelled: the run will not change again and its trace and metrics are stored. An
// interrupted run is not ended: it waits to be re-queued (or was not allowed to be).
bool Ended(RunStatus s);

}  // namespace vb
