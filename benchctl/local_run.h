// benchctl's local mode: the run pipeline (runs/) in process, on the local emulator bench, no server.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/run_key.h"
#include "common/status.h"
#include "db/store.h"
#include "experiment/runner.h"
#include "experiment/spec.h"

namespace vb::benchctl {

struct LocalRunResult {
  std::int64_t run_id = 0;            // in the local store (0 when not stored: --no-store)
  std::int64_t batch_id = 0;
  RunKey key;
  std::vector<std::string> tags;
  std::string controller;
  experiment::RunSummary summary;
  experiment::Trace trace;            // empty unless asked for
};

struct LocalSubmission {
  std::vector<experiment::ExperimentSpec> specs;
  std::vector<RunKey> keys;           // empty, or one per already expanded spec (runs::Submission::keys)
  std::string batch_name;
  std::string batch_json;             // "" = the spec, when there is one
  bool realtime = false;              // pace every run to the wall clock (sets the specs' `realtime`)
  bool keep_traces = false;
  std::string store_path;             // "" = --no-store: an in-memory store, nothing kept
};

// runs::Admit with the local emulator as the only bench and no limits, runs::Enqueue into the local store,
// then a runs::Worker on the calling thread until the batch is done (in the store's claim order: priority,
// then age). Runs of the local bench left queued by an interrupted invocation are cancelled first.
// `store` (optional): an open store to use instead of opening store_path (the local backend keeps one).
StatusOr<std::vector<LocalRunResult>> RunLocal(LocalSubmission submission, db::Store* store = nullptr);

// Where local runs are recorded: $VALVEBENCH_DB, else ~/.local/share/valvebench/local.db, else ./valvebench-local.db.
std::string DefaultLocalStorePath();

Status WriteTraceCsv(const experiment::Trace& trace, const std::string& path);

}  // namespace vb::benchctl
