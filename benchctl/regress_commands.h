// benchctl's regression commands (docs/regress.md):
//   baseline set NAME (--batch B | --suite SUITE) [--local | --server ADDR] [--note TEXT]
//   baseline list | baseline show NAME [--version N] [--local | --server ADDR]  (show --json: the baseline file)
//   regress SUITE --baseline NAME|FILE.json [--local | --server ADDR] [--junit FILE] [--json] [--seed N]
// Baselines and regression results live in the store of the service that runs the suite: the server's with
// --server (the lab's shared history, beside its nights), else the local store (--db); a baseline can also be a
// JSON file, wherever the suite runs (CI). benchctl reaches them through the service's RPCs (client::Client).
// Exit codes: 0 nothing regressed; 1 a regression or a failed run; 2 bad input or refused; 3 environment.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "client/client.h"

namespace vb::benchctl {

// benchctl's shared options, owned by main(): the new subcommands bind the same variables.
struct SharedOptions {
  bool* json;
  std::string* server;
  std::string* token;
  std::string* tls_ca_file;
  std::string* store_path;  // local store ("" after --no-store)
};

// --server, --token and --tls-ca on a subcommand: one wording for every command that can reach a server.
inline void AddServerOptions(CLI::App* sub, std::string* server, std::string* token, std::string* tls_ca_file) {
  sub->add_option("--server", *server, "bench server address host:port (or VALVEBENCH_SERVER)");
  sub->add_option("--token", *token, "bearer token (or VALVEBENCH_TOKEN)");
  sub->add_option("--tls-ca", *tls_ca_file, "PEM file of the CA that signed the server's certificate");
}
inline void AddServerOptions(CLI::App* sub, const SharedOptions& shared) {
  AddServerOptions(sub, shared.server, shared.token, shared.tls_ca_file);
}

using ClientFactory = std::function<std::unique_ptr<client::Client>()>;

class RegressCli {
 public:
  RegressCli(CLI::App* app, SharedOptions shared);
  bool parsed() const;
  int Run(const ClientFactory& make_client);

 private:
  SharedOptions shared_;
  CLI::App* baseline_ = nullptr;
  CLI::App* baseline_set_ = nullptr;
  CLI::App* baseline_list_ = nullptr;
  CLI::App* baseline_show_ = nullptr;
  CLI::App* regress_ = nullptr;
  CLI::App* nights_ = nullptr;
  int limit_ = 10;
  std::string name_, suite_path_, note_, baseline_arg_, junit_path_;
  std::int64_t batch_ = 0;
  int version_ = 0;
  std::uint64_t seed_ = 0;
  bool local_ = false;
};

}  // namespace vb::benchctl
