// valvebench-server configuration: loaded from protobuf JSON (proto/valvebench/v1/config.proto), validated
// with errors that name the field, defaults applied.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "runs/admit.h"
#include "runs/bench_setup.h"
#include "regress/compare.h"
#include "service/settings.h"
#include "valvebench/v1/config.pb.h"

namespace vb::server {

// Retention on a schedule (config "retention"; docs/store.md "Retention", docs/server.md).
struct RetentionSetup {
  bool enabled = false;
  double older_than_days = 0.0;  // > 0
  int keep_last = 0;             // >= 0
  std::string cron = "30 3 * * *";  // validated 5-field expression, UTC
};

// The server's whole configuration: what the service needs (service/settings.h) and the server's own parts.
struct Settings : ServiceSettings {
  std::string listen_address = "127.0.0.1:50051";
  std::string database_path;
  std::string tls_cert_pem, tls_key_pem;  // both set = TLS
  RetentionSetup retention;
  // The web dashboard's "host:port" (config "web"; docs/web.md); empty = no dashboard.
  std::string web_listen_address;
  valvebench::v1::WebConfig web;  // the whole block, limits checked (0 = default)
  // Where the dashboard keeps its sessions over a restart (web.sessions_file and its defaults); empty: in memory.
  std::string web_sessions_file;
  // The host's spool (config spool_dir, spool_max_mb; runs/spool.h): "" = none.
  std::string spool_dir;
  std::uint64_t spool_max_bytes = std::uint64_t{1} << 30;
};

StatusOr<Settings> LoadSettings(const std::string& config_path);
StatusOr<Settings> SettingsFromConfig(const valvebench::v1::ServerConfig& config, const std::string& base_dir);


}  // namespace vb::server
