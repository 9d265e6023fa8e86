// What the BenchService needs to know of its configuration (issue 27): its benches, who may call it, the limits
// it admits runs under, the lab identity it claims as, and the nights' baseline file its prune rules protect.
// valvebench-server's Settings (server/config.h) extends this with ports, TLS, the web door and the schedules;
// a local service (service/local_service.h) fills it in itself. Arrows point down: nothing here knows server/.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "runs/admit.h"
#include "runs/bench_setup.h"
#include "service/auth.h"
#include "valvebench/v1/config.pb.h"

namespace vb::server {

using runs::BenchSetup;

// The nightly regression (config "nights"; docs/regress.md). Paths resolved against the config's directory.
struct NightsSetup {
  bool enabled = false;
  std::string cron;             // validated 5-field expression
  std::string suite_path;
  std::string baseline_path;
  bool utc = true;              // the only time zone supported
  std::string lab_host;         // in a lab: this host's name; a night runs only where ClaimNight wins it
  double lab_lease_ttl_s = 0.0; // in a lab: a host whose heartbeat is 3 of these behind this host's is gone
};

// The lab (config "lab"; docs/lab.md). Disabled: one machine, no host name, no leases.
struct LabSetup {
  bool enabled = false;
  std::string host;                // default: hostname
  std::string advertised_address;  // "" = the bound listen address (filled in by main once bound)
  double lease_ttl_s = 10.0;
  double heartbeat_s = 10.0 / 3.0;
  double aging_s = 60.0;           // 0 = no aging
};

struct ServiceSettings {
  std::vector<BenchSetup> benches;
  Authenticator auth;
  valvebench::v1::Limits limits;          // defaults filled in
  // Set: admission uses these limits instead of `limits` (a local service: none but its trace budget).
  std::optional<runs::Limits> admit_limits;
  // What submissions are admitted with (runs/admit.h): the limits above and the configured benches.
  runs::Policy AdmitPolicy() const;
  NightsSetup nights;                     // the service reads baseline_path (prune keeps its batch)
  LabSetup lab;
};

}  // namespace vb::server
