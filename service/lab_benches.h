// The benches of a lab's other hosts as the service admits runs against them (docs/lab.md, "Hosts"): read back
// from the benches_json each host writes with its heartbeat (server/lab.h BenchesJson writes it).
#pragma once

#include <string>
#include <vector>

#include "db/store.h"
#include "runs/bench_setup.h"

namespace vb::server {

// The benches the other hosts registered (their heartbeats' benches_json, with capabilities), as BenchSetups that
// admission matches runs against: a run any host of the lab can take is accepted by every host.
std::vector<runs::BenchSetup> OtherHostsBenches(const std::vector<db::HostRecord>& hosts, const std::string& own_host);

}  // namespace vb::server
