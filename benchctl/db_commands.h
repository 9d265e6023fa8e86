// benchctl db: the store itself (docs/store.md, "PostgreSQL"; docs/cli.md).
//   db info [--db LOCATION | --server ADDR | --local] [--json]
//       engine, where, schema version, runs by status, rows per table, trace bytes, as the service's DescribeStore
//       RPC counts them. LOCATION: a SQLite file or a PostgreSQL connection string (postgresql://..., "host=...
//       dbname=..."), read by a local service started over it; --db given wins, else the server if one is given
//       (--server or VALVEBENCH_SERVER) and not --local, else the default local store.
//   db copy --from FILE.db --to postgresql://... [--into-non-empty] [--json]
//       moves a SQLite store's history into PostgreSQL, keeping ids: runs, status history, metrics, tags, sweep
//       points, traces as stored, batches, baselines, regression results. One transaction: all or nothing.
// Exit codes: 0 done; 2 refused (bad input, a non-empty target, running runs in the source); 3 environment
// (database unreachable, I/O).
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "benchctl/regress_commands.h"

namespace vb::benchctl {

class DbCli {
 public:
  // shared: the global --json, server options and local store (--db's default).
  DbCli(CLI::App* app, SharedOptions shared);
  bool parsed() const { return cmd_->parsed(); }
  int Run(const ClientFactory& make_client);

 private:
  SharedOptions shared_;
  bool local_ = false;
  CLI::App* cmd_ = nullptr;
  CLI::App* info_ = nullptr;
  CLI::App* copy_ = nullptr;
  std::string from_, to_;
  bool into_non_empty_ = false;
};

}  // namespace vb::benchctl
