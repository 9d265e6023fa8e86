#include "benchctl/hw_commands.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <iostream>

#include "benchctl/cli_common.h"

namespace vb::benchctl {

namespace {

void PrintAttached(const valvebench::v1::ListBenchesResponse& r) {
  std::printf("attached USB devices:%s\n", r.attached().empty() ? " none" : "");
  for (const auto& a : r.attached())
    std::printf("  %-4s %04x:%04x  serial %-14s %-20s %s\n", a.kind().c_str(), a.vendor_id(), a.product_id(),
                a.serial().empty() ? "?" : a.serial().c_str(), a.product().c_str(), a.path().c_str());
  if (!r.attached_note().empty()) std::printf("  (%s)\n", r.attached_note().c_str());
}

// A fault reason in the table: the table stays within 120 columns; --json has it whole.
std::string Clip(const std::string& s, std::size_t n) { return s.size() <= n ? s : s.substr(0, n - 3) + "..."; }

}  // namespace

int CmdBenches(Backend& backend, bool json) {
  auto r = backend.Benches();
  if (!r.ok()) return Fail(r.status());
  if (json) {
    std::string out;
    google::protobuf::util::JsonPrintOptions opts;
    opts.add_whitespace = true;
    opts.preserve_proto_field_names = true;
    opts.always_print_primitive_fields = true;
    (void)google::protobuf::util::MessageToJsonString(*r, &out, opts);
    std::cout << out << "\n";
    return kExitOk;
  }
  // A lab (docs/lab.md): every host's benches, with the host and whether it is alive (heartbeat within the TTL).
  const bool lab = std::any_of(r->benches().begin(), r->benches().end(), [](const auto& x) { return !x.host().empty(); });
  for (const auto& x : r->benches()) {
    const std::string state = x.busy()             ? "busy (run " + std::to_string(x.current_run_id()) + ")"
                              : !x.fault().empty() ? "FAULTED: " + Clip(x.fault(), 60)
                                                   : "idle";
    if (lab) {
      const std::string live = x.alive() ? "alive" : "DOWN, last heartbeat " + std::to_string(std::lround(x.heartbeat_age_s())) + " s ago";
      std::printf("%-12s %-16s %-9s %-18s %-16s %-8s %-16s %s (%s)\n", x.host().c_str(), x.name().c_str(),
                  x.kind().c_str(), x.driver().c_str(), x.model().c_str(), x.paced() ? "paced" : "", state.c_str(),
                  live.c_str(), x.host_address().c_str());
    } else {
      std::printf("%-16s %-9s %-18s %-16s %s\n", x.name().c_str(), x.kind().c_str(), x.driver().c_str(),
                  x.model().c_str(), state.c_str());
    }
  }
  PrintAttached(*r);
  return kExitOk;
}

}  // namespace vb::benchctl
