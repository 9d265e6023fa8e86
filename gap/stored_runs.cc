#include "gap/stored_runs.h"
#include "model/params.h"

#include <algorithm>

namespace vb::gap {

StoredRun StoredRunOf(std::int64_t id, const RunKey& key, const valvebench::v1::ExperimentSpec& spec,
                      double started_unix_s, std::optional<double> t_start_s, std::string split) {
  StoredRun s;
  s.id = id;
  s.name = key.DisplayName();
  s.supply_V = spec.conditions().supply_v();
  s.supply_pressure_Pa = spec.conditions().supply_pressure_pa();
  s.preset = spec.bench().model().preset();
  s.started_unix_s = started_unix_s;
  s.t_start_s = t_start_s;
  s.split = std::move(split);
  return s;
}

StatusOr<Dataset> DatasetOfStoredRuns(std::vector<StoredRun> runs) {
  if (runs.empty()) return Status::InvalidArgument("run_ids: at least one run is needed");
  Dataset ds;
  ds.format = std::string(kFormatValveRuns1);
  const double first_start_unix = runs.front().started_unix_s;
  for (std::size_t k = 0; k < runs.size(); ++k) {
    StoredRun& s = runs[k];
    const std::string where = "run " + std::to_string(s.id);
    if (s.gate.size() != s.i_A.size() || s.gate.empty())
      return Status::InvalidArgument(where + ": the trace has no gate and i_A channels of one length");
    RunData r;
    r.id = std::to_string(s.id) + ":" + s.name;
    r.file = where;
    r.supply_V = s.supply_V;
    r.supply_pressure_Pa = s.supply_pressure_Pa;
    r.sample_period_s = s.sample_period_s;
    r.i_A = std::move(s.i_A);
    r.gate.reserve(s.gate.size());
    r.t_s.reserve(s.gate.size());
    for (std::size_t j = 0; j < s.gate.size(); ++j) {
      const double g = s.gate[j];
      if (g != 0.0 && g != 1.0)
        return Status::InvalidArgument(where + ": gate[" + std::to_string(j) + "] is " + std::to_string(g) +
                                       "; the diagnosis needs a low-side switch command (0 or 1)");
      r.gate.push_back(static_cast<std::int8_t>(g));
      r.t_s.push_back(static_cast<double>(j) * r.sample_period_s);
    }
    // Imported runs carry their session's start time and split as fields (docs/server.md); other runs take
    // the start from when they ran.
    r.t_start_s = s.t_start_s ? *s.t_start_s : s.started_unix_s - first_start_unix;
    auto split = ParseSplit(s.split);
    r.split = split.ok() ? *split : Split::kNone;  // the store checked it when the run was imported
    if (k == 0) ds.model = s.preset.empty() ? model::kDefaultPreset : s.preset;
    ds.runs.push_back(std::move(r));
  }
  std::stable_sort(ds.runs.begin(), ds.runs.end(),
                   [](const RunData& a, const RunData& b) { return a.t_start_s < b.t_start_s; });
  // A split only if every run has one (as for a manifest); otherwise the diagnosis makes its own.
  const bool all_split = std::all_of(ds.runs.begin(), ds.runs.end(), [](const RunData& r) { return r.split != Split::kNone; });
  if (!all_split)
    for (auto& r : ds.runs) r.split = Split::kNone;
  return ds;
}

}  // namespace vb::gap
