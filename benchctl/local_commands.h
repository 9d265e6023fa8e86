// benchctl compare: results files from `run --json`, a spec run on the embedded emulator, or stored runs.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "benchctl/backend.h"
#include "experiment/compare.h"

namespace vb::benchctl {

// compare RESULTS.json (from run --json).
int CmdCompare(const std::string& input, bool json, bool csv, const experiment::TableOptions& table = {});
// compare --local SPEC: runs the spec's batch on the backend (a local service), waits, compares the batch.
int CmdCompareSpec(Backend& backend, const std::string& spec_path, bool json, bool csv,
                   const experiment::TableOptions& table = {});

// compare --batch B / --runs A,B,...: stored runs on either backend (--local: the local store), rendered by
// the comparison's one renderer.
int CmdCompareStored(Backend& backend, std::int64_t batch, const std::vector<std::int64_t>& run_ids, bool json,
                     bool csv, const experiment::TableOptions& table = {});
// The comparison as a table, CSV or JSON on stdout (experiment/compare.h renderers).
// table: --metrics/--wide (an unknown metric name is refused, exit 2).
int PrintComparison(const experiment::Comparison& c, bool json, bool csv, const experiment::TableOptions& table = {});

}  // namespace vb::benchctl
