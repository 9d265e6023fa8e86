// A lab's benches in both directions (docs/lab.md, "Hosts"): the one description of a configured bench
// (ListBenches, the heartbeat's benches_json), and the other hosts' benches read back from their heartbeats as
// the service admits runs against them.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "db/records.h"
#include "runs/bench_setup.h"
#include "valvebench/v1/api.pb.h"

namespace vb::server {

// The one description of a configured bench (ListBenches, the lab's heartbeat, every host's `benches`): what
// it is and its limits. The state (busy, current run, fault) and the lab fields (host, alive) are the caller's.
valvebench::v1::BenchInfo DescribeBench(const runs::BenchSetup& bench);
// The host's benches as HostRecord::benches_json: an array of DescribeBench's protobuf JSON (field names as in
// api.proto: "name", "kind", "model", "max_supply_V", ...) with "bench_class" and "caps" (what admission on
// another host checks a run against) beside them.
std::string BenchesJson(const std::vector<runs::BenchSetup>& benches);
// A bench another host registered (one element of its benches_json), as BenchInfo. InvalidArgument when it
// is not such an object.
StatusOr<valvebench::v1::BenchInfo> RegisteredBench(const std::string& bench_json);
// The benches the other hosts registered (their heartbeats' benches_json, with capabilities), as BenchSetups that
// admission matches runs against: a run any host of the lab can take is accepted by every host.
std::vector<runs::BenchSetup> OtherHostsBenches(const std::vector<db::HostRecord>& hosts, const std::string& own_host);

}  // namespace vb::server
