// benchctl's local mode: run specs on the embedded emulator, no server.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "experiment/runner.h"

namespace vb::benchctl {

struct LocalRunResult {
  std::string name;                   // spec name + sweep/repeat tags
  std::vector<std::string> tags;
  std::string controller;
  experiment::RunSummary summary;
  experiment::Trace trace;
};

// Expands, builds and runs every point of the spec on a fresh EmulatedBench built from the spec's model.
StatusOr<std::vector<LocalRunResult>> RunLocal(const experiment::ExperimentSpec& spec, bool realtime, bool keep_traces);

Status WriteTraceCsv(const experiment::Trace& trace, const std::string& path);

}  // namespace vb::benchctl
