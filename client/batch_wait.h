// Waiting for a batch, as every door that waits does it (`benchctl run --local`'s batches, `compare --local
// SPEC`): each run followed (WatchRun) until it has ended, in order, then `on_ended` called with its id.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "client/client.h"
#include "common/status.h"

namespace vb::client {

// Per run: at most deadline_s of watching. An error says "waiting for run N: ...".
Status WaitForRuns(Client& client, const std::vector<std::int64_t>& run_ids, double deadline_s,
                   const std::function<void(std::int64_t run_id)>& on_ended = {});

}  // namespace vb::client
