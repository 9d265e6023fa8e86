#include "client/batch_wait.h"

#include <string>

#include "common/run_status.h"
#include "proto/api_convert.h"

namespace vb::client {

Status WaitForRuns(Client& client, const std::vector<std::int64_t>& run_ids, double deadline_s,
                   const std::function<void(std::int64_t run_id)>& on_ended) {
  for (const std::int64_t id : run_ids) {
    // Sample rate 0: status and progress only, no live samples.
    const Status st = client.Watch(id, deadline_s, 0.0, [](const valvebench::v1::RunEvent& ev) {
      const auto status = api::FromProto(ev.status());
      return !(status && Ended(*status));
    });
    if (!st.ok()) return st.WithContext("waiting for run " + std::to_string(id));
    if (on_ended) on_ended(id);
  }
  return Status::Ok();
}

}  // namespace vb::client
