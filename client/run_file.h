// A run as an export file (export/run_file.h: HDF5 and MATLAB .mat), the one assembly for every door:
// `benchctl export --hdf5/--mat` and the web's trace.h5/.mat. The run's identity, status (common/run_status.h's
// words), spec, conditions and finite metrics with their units, and the trace's channels with theirs ("t_s"
// first: the stored time column, else the rows' times on the trace's time base).
#pragma once

#include <cstddef>

#include "client/client.h"
#include "common/status.h"
#include "common/trace_columns.h"
#include "export/run_file.h"
#include "valvebench/v1/api.pb.h"

namespace vb::client {

exportfile::RunFile RunFileOf(const valvebench::v1::Run& run, TraceColumns trace);

// Fetches the run's trace and assembles its file. max_trace_bytes > 0: a trace that reaches past it (chunk data
// and row times as received) is abandoned with ResourceExhausted "run N: the trace is larger than M MiB" (a door
// that builds the file in memory); its other errors are the call's (client.With's rpc_status has the gRPC one).
StatusOr<exportfile::RunFile> FetchRunFile(Client& client, const valvebench::v1::Run& run,
                                           std::size_t max_trace_bytes = 0, double deadline_s = 600.0);

}  // namespace vb::client
