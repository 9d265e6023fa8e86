// valvebench-server configuration: loaded from protobuf JSON (proto/valvebench/v1/config.proto), validated
// with errors that name the field, defaults applied.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "hw/emulated_bench.h"
#include "hw/safety.h"
#include "regress/compare.h"
#include "server/auth.h"
#include "valvebench/v1/config.pb.h"

namespace vb::server {

struct BenchSetup {
  std::string name;
  std::string kind;             // "emulated", "hid", "u3"
  std::string bench_class;      // what runs are matched on: "emulated:<preset>", "hid", "u3"
  std::string preset;
  valvebench::v1::ModelSpec model;
  hw::EmulatedBenchOptions emulated;
  valvebench::v1::BenchConfig config;  // as configured (hardware: which device)
  hw::Capabilities caps;        // what submissions are checked against
  hw::SafetyLimits safety;      // the interlocks every run on this bench goes through
  std::string device;           // hardware: "hid 2e8a:10c0 serial X", "u3 serial N"
};

// The nightly regression (config "nights"; docs/regress.md). Paths resolved against the config's directory.
struct NightsSetup {
  bool enabled = false;
  std::string cron;             // validated 5-field expression
  std::string suite_path;
  std::string baseline_path;
  bool utc = true;              // the only time zone supported
};

struct Settings {
  std::string listen_address = "127.0.0.1:50051";
  std::string database_path;
  std::vector<BenchSetup> benches;
  Authenticator auth;
  std::string tls_cert_pem, tls_key_pem;  // both set = TLS
  valvebench::v1::Limits limits;          // defaults filled in
  NightsSetup nights;
};

StatusOr<Settings> LoadSettings(const std::string& config_path);
StatusOr<Settings> SettingsFromConfig(const valvebench::v1::ServerConfig& config, const std::string& base_dir);

// A baseline JSON file as `benchctl baseline show --json` writes it (nights.baseline_file).
StatusOr<regress::Baseline> LoadBaselineFile(const std::string& path);

// The bench class a spec asks for ("emulated:<preset>"), as matched against BenchSetup::bench_class.
std::string SpecBenchClass(const valvebench::v1::ExperimentSpec& spec);

}  // namespace vb::server
