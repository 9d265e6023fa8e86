// The runs of a report as every door gathers them (`benchctl report --batch/--run`, the web's
// /api/batches/N/report.html): each run with its spec, metrics and times (report::RunInfo), and the traces of
// the ended runs, in run order, within a count and a size; and the batch report's title.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "client/client.h"
#include "common/status.h"
#include "report/report.h"
#include "valvebench/v1/api.pb.h"

namespace vb::client {

struct ReportLimits {
  int max_traces = 100;             // runs with their trace, at most (benchctl report --max-traces)
  std::size_t max_trace_bytes = 0;  // the traces' chunk data in all, at most (0 = no limit)
};

struct ReportRuns {
  std::vector<report::RunInfo> runs;  // in run id order
  int traces_left_out = 0;            // ended runs shown without their trace (past either limit)
};

// A run as the report takes it, without its trace.
report::RunInfo RunInfoOf(const valvebench::v1::Run& run);

// batch != 0: every run of the batch (NotFound "batch N: no runs" when it has none); else the listed runs.
// An ended run without a stored trace (NOT_FOUND) is shown without one; a trace that does not decode is
// DataLoss "run N: its trace's chunks do not decode".
StatusOr<ReportRuns> FetchReportRuns(Client& client, std::int64_t batch, const std::vector<std::int64_t>& run_ids,
                                     const ReportLimits& limits);

// "Batch 7: compare-current-controllers": the batch and its first run's spec name before any '/' (a variant).
std::string BatchReportTitle(std::int64_t batch, const std::vector<report::RunInfo>& runs);

}  // namespace vb::client
