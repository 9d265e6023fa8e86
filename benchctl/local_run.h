// benchctl's local mode: run specs on the embedded emulator, no server.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "experiment/runner.h"

namespace vb::benchctl {

struct LocalRunResult {
  std::int64_t run_id = 0;            // in the local store (0 when not stored)
  std::int64_t batch_id = 0;
  std::string name;                   // spec name + sweep/repeat tags
  std::vector<std::string> tags;
  std::string controller;
  experiment::RunSummary summary;
  experiment::Trace trace;
};

// Expands, builds and runs every point of the spec on a fresh EmulatedBench built from the spec's model.
// With a store path, the batch is recorded there exactly as a server records it (spec, status history,
// metrics, trace), and the runs execute in the store's claim order (priority, then age).
StatusOr<std::vector<LocalRunResult>> RunLocal(const experiment::ExperimentSpec& spec, bool realtime, bool keep_traces,
                                               const std::string& store_path = "");

// The same for points already expanded (single-run specs, e.g. a regression suite's runs), recorded as one batch.
StatusOr<std::vector<LocalRunResult>> RunLocalPoints(const std::vector<experiment::ExperimentSpec>& points,
                                                     const std::string& batch_name, const std::string& batch_json,
                                                     bool realtime, bool keep_traces, const std::string& store_path);

// Where local runs are recorded: $VALVEBENCH_DB, else ~/.local/share/valvebench/local.db, else ./valvebench-local.db.
std::string DefaultLocalStorePath();

Status WriteTraceCsv(const experiment::Trace& trace, const std::string& path);

}  // namespace vb::benchctl
