// A stored trace as CSV, the one writer for every door (benchctl export --csv/--trace-csv, run --trace-csv from
// the service, the web's trace.csv): "t_s" then every other channel in the stored order, one row per sample,
// numbers by common/csv.h (NaN: an empty field). t_s is the stored time column when the trace has one, else the
// row's time on the trace's time base. Written chunk by chunk (client/trace_stream.h) or from a whole trace.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>

#include "client/trace_stream.h"
#include "common/status.h"
#include "common/trace_columns.h"

namespace vb::client {

// "t_s,gate,i_A\n": the header row of `trace`'s channels.
std::string TraceCsvHeader(const TraceColumns& trace);
// Appends `rows`'s rows; first_row: the index of its first row in the whole trace (TraceStream::first_row()).
void AppendTraceCsvRows(const TraceColumns& rows, std::int64_t first_row, std::string* out);
// The whole trace (header and rows).
std::string TraceCsv(const TraceColumns& trace);
// The whole trace to `f`, a block of rows in memory at a time; `what` names `f` in errors.
Status WriteTraceCsv(const TraceColumns& trace, std::FILE* f, const std::string& what);
// The rest of `stream` (its current rows first) to `f`, a chunk in memory at a time; `what` names `f` in errors.
Status WriteTraceCsv(TraceStream& stream, std::FILE* f, const std::string& what);

}  // namespace vb::client
