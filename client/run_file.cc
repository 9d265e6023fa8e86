#include "client/run_file.h"

#include <fmt/format.h>

#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "client/trace_stream.h"
#include "common/run_status.h"
#include "experiment/spec.h"
#include "proto/api_convert.h"

namespace vb::client {

namespace v1 = valvebench::v1;

exportfile::RunFile RunFileOf(const v1::Run& run, TraceColumns trace) {
  exportfile::RunFile f;
  f.run_id = run.id();
  f.name = run.name();
  f.controller = run.controller();
  f.bench = run.bench();
  f.status = RunStatusName(api::FromProto(run.status()).value_or(RunStatus::kQueued));
  f.reason = run.reason();
  f.spec_json = experiment::SpecToJson(run.spec(), /*pretty=*/false);
  f.conditions = {{"supply_V", run.spec().conditions().supply_v(), "V"},
                  {"supply_pressure_Pa", run.spec().conditions().supply_pressure_pa(), "Pa"}};
  const std::map<std::string, double> metrics(run.metrics().begin(), run.metrics().end());  // sorted: a stable file
  for (const auto& [name, value] : metrics)
    if (std::isfinite(value)) f.metrics.push_back({name, value, exportfile::MetricUnit(name, f.controller)});
  f.t0_s = trace.t0_s;
  f.sample_period_s = trace.sample_period_s;
  std::vector<double> t;
  if (auto it = trace.columns.find("t_s"); it != trace.columns.end()) {
    t = std::move(it->second);
  } else {
    t.resize(trace.samples());
    for (std::size_t i = 0; i < t.size(); ++i) t[i] = trace.TimeAt(i);
  }
  f.channels.push_back({"t_s", exportfile::ChannelUnit("t_s", f.controller), std::move(t)});
  for (const auto& name : trace.channels)
    if (name != "t_s")
      f.channels.push_back({name, exportfile::ChannelUnit(name, f.controller), std::move(trace.columns[name])});
  return f;
}

StatusOr<exportfile::RunFile> FetchRunFile(Client& client, const v1::Run& run, std::size_t max_trace_bytes,
                                           double deadline_s) {
  v1::GetTraceRequest r;
  r.set_run_id(run.id());
  auto stream = client.OpenTrace(r, deadline_s);
  if (!stream.ok()) return stream.status();
  TraceStream& s = **stream;
  for (;;) {
    if (max_trace_bytes > 0 && s.bytes() > max_trace_bytes) {
      s.Abandon();
      return Status::ResourceExhausted(
          fmt::format("run {}: the trace is larger than {} MiB", run.id(), max_trace_bytes >> 20));
    }
    if (!s.Next()) break;
  }
  if (!s.status().ok()) return s.status().WithContext("run " + std::to_string(run.id()));
  return RunFileOf(run, s.TakeAll());
}

}  // namespace vb::client
