// benchctl's local commands (no server): run on the embedded emulator, compare, with the local store.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "benchctl/backend.h"
#include "experiment/compare.h"

namespace vb::benchctl {

// run --local SPEC: runs (and, with a store path, records) the batch; prints summaries, CSV or JSON.
int CmdRun(const std::string& spec_path, bool local, const std::string& store_path, const std::string& trace_csv,
           bool json, bool csv, bool realtime, const experiment::TableOptions& table = {});
// compare RESULTS.json (from run --json), or compare --local SPEC (runs it first).
int CmdCompare(const std::string& input, bool local, const std::string& store_path, bool json, bool csv,
               const experiment::TableOptions& table = {});

// compare --batch B / --runs A,B,...: stored runs on either backend (--local: the local store), rendered by
// the comparison's one renderer.
int CmdCompareStored(Backend& backend, std::int64_t batch, const std::vector<std::int64_t>& run_ids, bool json,
                     bool csv, const experiment::TableOptions& table = {});
// The comparison as a table, CSV or JSON on stdout (experiment/compare.h renderers).
// table: --metrics/--wide (an unknown metric name is refused, exit 2).
int PrintComparison(const experiment::Comparison& c, bool json, bool csv, const experiment::TableOptions& table = {});

}  // namespace vb::benchctl
