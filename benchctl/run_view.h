// A stored run as every benchctl command sees it, from either backend (benchctl/backend.h), and its one
// renderer: text for people, JSON and CSV for scripts. `run`, `show`, `queue`, `watch` and `cancel` print runs
// only through these functions, so a run looks the same whether it came from the local store or a server
// (docs/cli.md "One output convention").
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/run_key.h"
#include "common/run_status.h"
#include "valvebench/v1/api.pb.h"
#include "valvebench/v1/spec.pb.h"

namespace vb::benchctl {

struct RunChange {
  RunStatus status = RunStatus::kQueued;
  double at_unix_s = 0.0;
  std::string reason;
};

struct RunView {
  std::int64_t id = 0;                 // 0: not stored (run --local --no-store)
  std::int64_t batch_id = 0;
  RunKey key;
  std::string controller;
  RunStatus status = RunStatus::kQueued;
  std::string reason;
  std::map<std::string, double> metrics;  // finite metrics only
  std::string bench;                   // the bench that ran it (or was requested; "" = any)
  double result_waiting_since_unix_s = 0.0;  // running: its result waits in its host's spool since then
  std::string host;                    // a lab: the host executing it, or that last did ("" = one machine)
  double duration_s = 0.0;             // the spec's duration (0 = unknown)
  std::string submitter;
  int priority = 0;
  double progress = 0.0;               // 0..1
  double submitted_unix_s = 0.0, started_unix_s = 0.0, finished_unix_s = 0.0;  // 0 = not yet
  std::vector<std::string> tags;
  std::string split;                   // imported runs: "fit", "holdout" or ""
  std::optional<double> t_start_s;     // imported runs: start within the dataset's session
  std::optional<valvebench::v1::ExperimentSpec> spec;  // single runs (show, GetRun); not in listings
  std::vector<RunChange> history;      // single runs only
  // What executing it measured, stored with the run (absent: it did not execute); `loop` for paced runs only.
  std::optional<valvebench::v1::RunExecution> execution;

  bool ok() const { return status == RunStatus::kDone; }
  bool ended() const { return Ended(status); }
};

using Json = nlohmann::ordered_json;

// Metrics in one stable order everywhere: experiment::MetricList's order, then any other name alphabetically.
std::vector<std::pair<std::string, double>> OrderedMetrics(const std::map<std::string, double>& metrics);

// ISO 8601 in the local time zone with its offset, e.g. "2026-11-25T13:16:42+01:00"; "-" for 0 (not yet).
std::string IsoLocalTime(double unix_s);

// Text: identity and status, bench and times, what executing it measured (when it executed: wall time, samples,
// a paced loop's ticks, overruns and jitter), metrics with their SI units, and with `history` every status change.
std::string RunText(const RunView& run, bool history);
// JSON: numeric ids, the lower-case status words of common/run_status.h, times as ISO 8601 and Unix seconds,
// metrics in OrderedMetrics order; "summary" for a run that executed (with "loop" when it was paced);
// "id"/"batch_id" absent for a run that was not stored.
Json RunJson(const RunView& run);
// CSV: one header for a list of runs (a column per swept field any of them has, then status and times, then
// metric columns: every name any of them has), one row per run.
std::string RunsCsv(const std::vector<RunView>& runs);
// One line on an executed run, as experiment::RunSummary::BriefReport words it ("done: 0.5 s, 5001 samples,
// 5001 ticks, 180x real time"), from the stored run; its status word alone when it did not execute.
std::string ExecutionBrief(const RunView& run);

// One line for a run of a batch (run prints these, then the comparison carries the metrics):
// "run 12 static-map/fig8 duty=0.35 supply_pressure_Pa=200000: done", the sweep fields' last component.
std::string RunLine(const RunView& run);

// One line for a status/progress event (watch, run --wait): "run 5 running 40 %".
std::string EventText(const RunView& run);

}  // namespace vb::benchctl
