// benchctl's remote commands: the same verbs as the local mode, against a valvebench-server.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "client/client.h"

namespace vb::benchctl {

struct Output {
  bool json = false;
  bool csv = false;
};

int RemoteRun(client::Client& c, const std::string& spec_path, bool wait, const Output& out);
int RemoteQueue(client::Client& c, const std::string& status, std::int64_t batch, const std::string& tag,
                int limit, const Output& out);
int RemoteShow(client::Client& c, std::int64_t run_id, const Output& out);
int RemoteWatch(client::Client& c, std::int64_t run_id, const Output& out);
int RemoteCancel(client::Client& c, std::int64_t run_id, const std::string& reason, const Output& out);
int RemoteExport(client::Client& c, std::int64_t run_id, const std::string& csv_path);

}  // namespace vb::benchctl
