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
#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "model/params.h"

namespace vb::gap {

// A switch-on capture's artefacts, found and removed before a fit (issue 35, point 5). A real scope trace of a
// valve from rest is not the model's current: the probe or shunt amplifier adds a baseline offset, and the
// driver's switching edge couples a spike of either sign into the first samples after (or just before) the
// gate's edge.
//  - Baseline offset: the median of the pre-trigger samples (gate low, the coil at rest, so the true current
//    is 0). Removed when it exceeds 4 standard errors of that median (1.25 sigma / sqrt(n) for Gaussian noise):
//    a false removal then has a probability below 1e-4, and a removal smaller than that changes nothing a fit
//    can see.
//  - Switching spike: within the first 50 us around the edge (a driver's switching transient is a few us; 50 us
//    is 5 samples at 100 kHz), samples that stand out from the running median of 7 samples by more than 6 noise
//    sigmas. A coil current from rest rises monotonically over that span (an inductor with or without an eddy
//    branch: a jump at the edge, then a smooth rise), and a median of an odd window passes a monotone sequence
//    unchanged, so only a non-monotone excursion (the spike) is flagged. Flagged samples are masked: replaced by
//    that running median, and the report says how many and how large.
//  - Inverted polarity: a trace whose gate-on mean is negative beyond 6 sigmas (a probe or shunt wired the
//    other way) is negated; a coil driven from rest carries a positive current.
struct CaptureCleaning {
  double offset_A = 0.0;     // removed (0: none significant)
  int spike_samples = 0;     // masked at the edge
  double spike_A = 0.0;      // the largest masked excursion, signed
  bool inverted = false;     // the trace was negated
  std::string note;          // for the report ("" when nothing was done)
};
// noise_A: the trace's noise sigma (<= 0: estimated from second differences). Does nothing without a gate edge
// (every sample low, or high from the first).
CaptureCleaning CleanSwitchOnCapture(std::vector<double>* i_A, const std::vector<std::int8_t>& gate, double dt_s,
                                     double noise_A = 0.0);

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
  bool clean = true;              // remove the baseline offset, mask the edge spike, fix the polarity
};

struct ScopeRun {
  CaptureCleaning cleaning;  // what was removed before writing (an offset, a spike, the polarity)

  std::string directory, run_id, file;
  std::size_t samples = 0;
  double sample_period_s = 0.0, gate_on_s = 0.0;
};

// Errors name the file, the 1-based line and the column ("cap.csv:17: column CH2: 'x' is not a number").
StatusOr<ScopeRun> ConvertScopeCsv(const std::string& csv_path, const std::string& out_dir,
                                   const ScopeCsvOptions& options);

}  // namespace vb::gap
