// benchctl db: the store itself (docs/store.md, "PostgreSQL"; docs/cli.md).
//   db info [--db LOCATION] [--json]
//       engine, where, schema version, runs by status, rows per table, trace bytes. LOCATION: a SQLite file or a
//       PostgreSQL connection string (postgresql://..., "host=... dbname=...").
//   db copy --from FILE.db --to postgresql://... [--into-non-empty] [--json]
//       moves a SQLite store's history into PostgreSQL, keeping ids: runs, status history, metrics, tags, sweep
//       points, traces as stored, batches, baselines, regression results. One transaction: all or nothing.
// Exit codes: 0 done; 2 refused (bad input, a non-empty target, running runs in the source); 3 environment
// (database unreachable, I/O).
#pragma once

#include <CLI/CLI.hpp>
#include <string>

namespace vb::benchctl {

class DbCli {
 public:
  // json: the global --json flag; store_path: the global local store (--db's default).
  DbCli(CLI::App* app, bool* json, std::string* store_path);
  bool parsed() const { return cmd_->parsed(); }
  int Run();

 private:
  bool* json_;
  std::string* store_path_;
  CLI::App* cmd_ = nullptr;
  CLI::App* info_ = nullptr;
  CLI::App* copy_ = nullptr;
  std::string from_, to_;
  bool into_non_empty_ = false;
};

}  // namespace vb::benchctl
