// Importer for valve-runs/1 datasets: measured valve runs to compare with a nominal model (the sim-to-real gap).
// A dataset is a directory with manifest.json and one CSV file per run; docs/dataset-format.md gives the format
// as accepted here, every validation rule and its error message.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"

namespace vb::gap {

inline constexpr std::string_view kFormatValveRuns1 = "valve-runs/1";

// One run: the manifest entry and its CSV columns (all columns have the same length, >= 2 samples).
struct RunData {
  std::string id;
  std::string file;                     // as written in the manifest, relative to the dataset directory
  double supply_V = 0.0;                // > 0
  double supply_pressure_Pa = 0.0;      // >= 0
  double t_start_s = 0.0;               // >= 0, seconds since the bench was powered
  std::string split;                    // "fit", "holdout", or "" if absent
  double sample_period_s = 0.0;         // (t_s.back() - t_s.front()) / (samples - 1)
  std::vector<double> t_s;              // starts at 0 (within 1e-9 s), uniform
  std::vector<int8_t> gate;             // 0 or 1
  std::vector<double> i_A;
  std::vector<double> x_m;              // empty if the column is absent
  std::vector<double> v_coil_V;         // empty if the column is absent
};

struct Dataset {
  std::string format;                   // "valve-runs/1"
  std::string model;                    // one of the known model names
  std::string description;              // "" if absent
  std::string directory;                // as passed to LoadDataset
  std::vector<RunData> runs;            // in manifest order (= time order)
  // What was ignored: unknown CSV columns, unknown manifest keys. Each names the file (and the run).
  std::vector<std::string> warnings;
};

// The model names accepted when the caller passes none: {"taghizadeh2009"}. Callers that know the model
// presets pass them instead (e.g. model::PresetNames()).
std::vector<std::string> DefaultKnownModels();

// Loads and validates a dataset directory. Every violation is InvalidArgument with a message that starts with
// the file ("<dataset>/manifest.json: runs[3].split: ...", "<dataset>/<file>.csv:1234: column i_A: ..."), where
// <dataset> is the last component of `directory`.
StatusOr<Dataset> LoadDataset(const std::string& directory,
                              const std::vector<std::string>& known_models = DefaultKnownModels());

}  // namespace vb::gap
