// benchctl prune: retention (docs/store.md, "Retention").
//   prune --older-than 30d [--keep-last N] [--dry-run] [--json] [--local [--db FILE] | --server ADDR]
// Deletes finished runs that ended longer ago than the age, with their traces, through the admin-only PruneRuns
// RPC of a server or of the local service over the local store (one set of prune rules, the service's). Never queued, running or interrupted runs, never runs of a
// batch that a baseline or a regression night or result references, never the newest N. Prints what it
// deleted (or would delete) and what it kept, and why. Exit 0 done, 2 bad input or refused, 3 environment.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>

#include "benchctl/regress_commands.h"  // SharedOptions
#include "common/status.h"

namespace vb::benchctl {

// "30d", "12h", "90m", "3600s", "2w" (a positive number and one unit) -> seconds; InvalidArgument naming
// --older-than otherwise.
StatusOr<double> ParseAge(const std::string& text);

class PruneCli {
 public:
  PruneCli(CLI::App* app, SharedOptions shared);
  bool parsed() const { return cmd_->parsed(); }
  int Run();

 private:
  SharedOptions shared_;
  CLI::App* cmd_ = nullptr;
  std::string older_than_;
  std::int32_t keep_last_ = 0;
  bool dry_run_ = false;
  bool local_ = false;
};

}  // namespace vb::benchctl
