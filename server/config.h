// valvebench-server configuration: loaded from protobuf JSON (proto/valvebench/v1/config.proto), validated
// with errors that name the field, defaults applied.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "runs/admit.h"
#include "runs/bench_setup.h"
#include "regress/compare.h"
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
};

// Retention on a schedule (config "retention"; docs/store.md "Retention", docs/server.md).
struct RetentionSetup {
  bool enabled = false;
  double older_than_days = 0.0;  // > 0
  int keep_last = 0;             // >= 0
  std::string cron = "30 3 * * *";  // validated 5-field expression, UTC
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

struct Settings {
  std::string listen_address = "127.0.0.1:50051";
  std::string database_path;
  std::vector<BenchSetup> benches;
  Authenticator auth;
  std::string tls_cert_pem, tls_key_pem;  // both set = TLS
  valvebench::v1::Limits limits;          // defaults filled in
  // What submissions are admitted with (runs/admit.h): the limits above and the configured benches.
  runs::Policy AdmitPolicy() const;
  NightsSetup nights;
  RetentionSetup retention;
  LabSetup lab;
  // The web dashboard's "host:port" (config "web"; docs/web.md); empty = no dashboard.
  std::string web_listen_address;
  valvebench::v1::WebConfig web;  // the whole block, limits checked (0 = default)
};

StatusOr<Settings> LoadSettings(const std::string& config_path);
StatusOr<Settings> SettingsFromConfig(const valvebench::v1::ServerConfig& config, const std::string& base_dir);

// A baseline JSON file as `benchctl baseline show --json` writes it (nights.baseline_file).
StatusOr<regress::Baseline> LoadBaselineFile(const std::string& path);

}  // namespace vb::server
