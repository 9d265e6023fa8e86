// Stored runs (a store's, or a server's) as a dataset for the diagnosis (docs/gap.md, "Stored runs"): what
// `benchctl diagnose --runs` and the server's DiagnoseRuns both build, from runs however they were fetched.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/run_key.h"
#include "common/status.h"
#include "gap/dataset.h"
#include "valvebench/v1/spec.pb.h"

namespace vb::gap {

struct StoredRun {
  std::int64_t id = 0;
  std::string name;                  // its display name (RunKey)
  double supply_V = 0.0;
  double supply_pressure_Pa = 0.0;
  std::string preset;                // the model preset it ran on or was imported against ("" = taghizadeh2009)
  double started_unix_s = 0.0;
  std::optional<double> t_start_s;   // imported runs: the start within their session
  std::string split;                 // imported runs: "fit", "holdout" or ""
  double sample_period_s = 0.0;
  std::vector<double> gate, i_A;     // the trace's channels
};

// A stored run's identity and conditions, from its record and its spec (conditions, model preset); the caller
// adds the trace (sample_period_s, gate, i_A). One place for benchctl's fetch and the server's store read.
StoredRun StoredRunOf(std::int64_t id, const RunKey& key, const valvebench::v1::ExperimentSpec& spec,
                      double started_unix_s, std::optional<double> t_start_s, std::string split);

// Each run becomes a measured waveform run: a low-side switch command (gate 0 or 1, else InvalidArgument naming
// the run and the sample), its current and conditions. Imported runs keep their session times and splits;
// other runs start when they ran, relative to the first. A split only if every run has one. The dataset's
// model is the first run's preset.
StatusOr<Dataset> DatasetOfStoredRuns(std::vector<StoredRun> runs);

}  // namespace vb::gap
