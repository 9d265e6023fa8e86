// A scope's CSV export of one capture -> one run of a valve-runs/2 dataset (issue 25, point 4).
//
// What common bench scopes write: some header lines (model, record length, units, or a column-name line), then
// one row per sample: a time column and one column per channel, comma (or semicolon/tab) separated. The time
// column is seconds (often negative before the trigger). The current channel is a shunt voltage (current =
// volts / shunt_ohm) or a current probe's output (current = volts x probe_A_per_V). The gate's rising edge
// comes from a channel (the gate drive: high above threshold_V) or is given as a trigger time.
// The run is written as t_s (from the first sample, 0-based), gate, i_A; the manifest is created, or the run
// appended to it (runs stay in time order by t_start_s).
#pragma once

#include <cmath>
#include <cstddef>
#include <string>

#include "common/status.h"
#include "model/params.h"

namespace vb::gap {

struct ScopeCsvOptions {
  std::string time_column;        // a column name or 1-based index; "" : the first column
  std::string current_channel;    // a column name or 1-based index (required)
  double shunt_ohm = 0.0;         // current = volts / shunt_ohm
  double probe_A_per_V = 0.0;     // or current = volts x probe_A_per_V (exactly one of the two)
  std::string gate_channel;       // a column with the gate drive, or
  double gate_threshold_V = NAN;  //   its high level threshold (NaN: halfway between its min and max)
  double trigger_s = NAN;         // the gate's rising edge in the time column's seconds
  // The run.
  std::string run_id;             // "" : the CSV's file name without extension
  double supply_V = 0.0;          // > 0
  double supply_pressure_Pa = 0.0;
  double t_start_s = NAN;         // NaN: after the dataset's last run (+1 s), or 0 for the first
  std::string split;              // "", "fit" or "holdout"
  std::string model = model::kDefaultPreset;
  std::string device;
  // The scope's chain (declared in the manifest's sensor; NaN / 0: not declared).
  double noise_A = NAN;
  int averaged = 0;
  double lsb_A = NAN;
};

struct ScopeRun {
  std::string directory, run_id, file;
  std::size_t samples = 0;
  double sample_period_s = 0.0, gate_on_s = 0.0;
};

// Errors name the file, the 1-based line and the column ("cap.csv:17: column CH2: 'x' is not a number").
StatusOr<ScopeRun> ConvertScopeCsv(const std::string& csv_path, const std::string& out_dir,
                                   const ScopeCsvOptions& options);

}  // namespace vb::gap
