// benchctl's run commands, written once against a Backend (the local store or a server) and printed through
// the one run renderer (benchctl/run_view.h):
//   run SPEC [--wait] [--trace-csv FILE] [--realtime] [--metrics a,b] [--wide]   queue a spec's runs (local: execute them now)
//   queue [--status S] [--batch B] [--tag T] [--limit N]   runs waiting or running (or matching the filter)
//   show RUN | watch RUN | cancel RUN [--reason TEXT]
//   export RUN [--csv] [--trace-csv FILE] [--hdf5 FILE] [--mat FILE]
// --json / --csv: JSON / CSV on stdout; progress goes to stderr (docs/cli.md).
#pragma once

#include <cstdint>
#include <string>

#include "benchctl/backend.h"
#include "experiment/compare.h"

namespace vb::benchctl {

struct Output {
  bool json = false;
  bool csv = false;
};

struct RunOptions {
  std::string spec_path;
  bool wait = false;          // remote: wait for the runs (local runs always complete before `run` returns)
  std::string trace_csv;      // local: the recorded channels as CSV (batches: FILE-<n>.csv)
  bool realtime = false;      // local: paced to the wall clock
  experiment::TableOptions table;  // a batch's comparison table: --metrics/--wide (docs/comparison.md)
};
int CmdRun(Backend& backend, const RunOptions& options, const Output& out);

struct QueueOptions {
  std::string status;         // "" = running and queued
  std::int64_t batch = 0;
  std::string tag;
  int limit = 100;
};
int CmdQueue(Backend& backend, const QueueOptions& options, const Output& out);

int CmdShow(Backend& backend, std::int64_t run_id, const Output& out);
// Exit 0 if the run succeeded, 1 if it failed or was cancelled.
int CmdWatch(Backend& backend, std::int64_t run_id, const Output& out);
// Waits up to cancel_wait_s for the run to reach its final state and reports the state it reached.
int CmdCancel(Backend& backend, std::int64_t run_id, const std::string& reason, const Output& out,
              double cancel_wait_s = 10.0);

struct ExportOptions {
  bool csv_stdout = false;    // --csv: the trace as CSV on stdout
  std::string trace_csv;      // --trace-csv FILE
  std::string hdf5;           // --hdf5 FILE
  std::string mat;            // --mat FILE
};
// json: {"id", "files": [{"format", "path"}]} on stdout once written (not with --csv: stdout is the CSV).
int CmdExport(Backend& backend, std::int64_t run_id, const ExportOptions& options, bool json);

}  // namespace vb::benchctl
