#include "benchctl/export_files.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>

#include "benchctl/cli_common.h"
#include "benchctl/remote.h"
#include "export/run_file.h"

namespace vb::benchctl {

namespace v1 = valvebench::v1;

namespace {

const char* StatusText(v1::RunStatus s) {
  switch (s) {
    case v1::QUEUED:
      return "queued";
    case v1::RUNNING:
      return "running";
    case v1::DONE:
      return "done";
    case v1::FAILED:
      return "failed";
    case v1::CANCELLED:
      return "cancelled";
    case v1::INTERRUPTED:
      return "interrupted";
    default:
      return "unspecified";
  }
}

}  // namespace

int RemoteExportFiles(client::Client& c, std::int64_t run_id, const std::string& csv_path, const std::string& hdf5_path,
                      const std::string& mat_path) {
  if (csv_path.empty() && hdf5_path.empty() && mat_path.empty())
    return Fail(Status::InvalidArgument("export: give --csv FILE, --hdf5 FILE or --mat FILE"));
  if (!csv_path.empty()) {
    const int rc = RemoteExport(c, run_id, csv_path);
    if (rc != kExitOk || (hdf5_path.empty() && mat_path.empty())) return rc;
  }
  auto run = c.GetRun(run_id);
  if (!run.ok()) return Fail(run.status());
  auto trace = c.GetTrace(run_id);
  if (!trace.ok()) return Fail(trace.status());

  exportfile::RunFile f;
  f.run_id = run->id();
  f.name = run->name();
  f.controller = run->controller();
  f.bench = run->bench();
  f.status = StatusText(run->status());
  f.reason = run->reason();
  f.t0_s = trace->t0_s;
  f.sample_period_s = trace->sample_period_s;
  google::protobuf::util::JsonPrintOptions opts;
  opts.preserve_proto_field_names = true;
  (void)google::protobuf::util::MessageToJsonString(run->spec(), &f.spec_json, opts);
  f.conditions = {{"supply_V", run->spec().conditions().supply_v(), "V"},
                  {"supply_pressure_Pa", run->spec().conditions().supply_pressure_pa(), "Pa"}};
  for (const auto& [name, value] : run->metrics())  // a protobuf map: sorted here for a stable file
    f.metrics.push_back({name, value, exportfile::MetricUnit(name, f.controller)});
  std::sort(f.metrics.begin(), f.metrics.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  for (const auto& name : trace->channels)
    f.channels.push_back({name, exportfile::ChannelUnit(name, f.controller), std::move(trace->columns.at(name))});

  if (!hdf5_path.empty())
    if (auto st = exportfile::WriteHdf5(f, hdf5_path); !st.ok()) return Fail(st);
  if (!mat_path.empty())
    if (auto st = exportfile::WriteMat(f, mat_path); !st.ok()) return Fail(st);
  return kExitOk;
}

}  // namespace vb::benchctl
