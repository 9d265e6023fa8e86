// A lab's benches in both directions (docs/lab.md, "Hosts"): the one description of a configured bench
// (ListBenches, the heartbeat's benches_json), and the other hosts' benches read back from their heartbeats as
// the service admits runs against them.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "common/status.h"
#include "db/records.h"
#include "runs/bench_setup.h"
#include "valvebench/v1/api.pb.h"
#include "valvebench/v1/config.pb.h"

namespace vb::server {

// The one description of a configured bench (ListBenches, the lab's heartbeat, every host's `benches`): what
// it is and its limits. The state (busy, current run, fault) and the lab fields (host, alive) are the caller's.
valvebench::v1::BenchInfo DescribeBench(const runs::BenchSetup& bench);
// What a bench can do, as a message (config.proto BenchCapabilities, its kind typed) and back. A kind the message
// does not give (BENCH_KIND_UNSPECIFIED) leaves hw::Capabilities::kind empty.
valvebench::v1::BenchCapabilities CapabilitiesToProto(const hw::Capabilities& caps);
hw::Capabilities CapabilitiesFromProto(const valvebench::v1::BenchCapabilities& caps);
// What another host needs of a configured bench (config.proto BenchRegistration): its class, capabilities, and
// its health check with what that check's runs carry.
valvebench::v1::BenchRegistration RegistrationOf(const runs::BenchSetup& bench);
// The host's benches as HostRecord::benches_json: an array of objects, each DescribeBench's and RegistrationOf's
// protobuf JSON (proto field names: "name", "kind", "max_supply_V", ..., "bench_class", "caps") side by side.
std::string BenchesJson(const std::vector<runs::BenchSetup>& benches);
// One entry of a host's benches_json as admission on another host uses it; nullopt when it is not a bench
// registration (no name or class, an unknown kind, or written by a build older than the capabilities).
std::optional<runs::BenchSetup> RegisteredSetup(const std::string& bench_json);
// A bench another host registered (one element of its benches_json), as BenchInfo. InvalidArgument when it
// is not such an object.
StatusOr<valvebench::v1::BenchInfo> RegisteredBench(const std::string& bench_json);
// The benches the other hosts registered (their heartbeats' benches_json, with capabilities), as BenchSetups that
// admission matches runs against: a run any host of the lab can take is accepted by every host.
std::vector<runs::BenchSetup> OtherHostsBenches(const std::vector<db::HostRecord>& hosts, const std::string& own_host);

}  // namespace vb::server
