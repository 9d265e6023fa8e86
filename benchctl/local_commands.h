// benchctl's local commands (no server): run on the embedded emulator, compare, with the local store.
#pragma once

#include <cstdint>
#include <string>

namespace vb::benchctl {

// run --local SPEC: runs (and, with a store path, records) the batch; prints summaries, CSV or JSON.
int CmdRun(const std::string& spec_path, bool local, const std::string& store_path, const std::string& trace_csv,
           bool json, bool csv, bool realtime);
// compare RESULTS.json (from run --json), or compare --local SPEC (runs it first).
int CmdCompare(const std::string& input, bool local, const std::string& store_path, bool json, bool csv);

// compare --local --batch B: a batch recorded in the local store.
int CmdCompareLocalBatch(const std::string& store_path, std::int64_t batch, bool json, bool csv);

}  // namespace vb::benchctl
