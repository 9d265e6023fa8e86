// Periodic steady-state readings in one CSV, one row per reading, as a PWM bench with a shunt, an amplifier
// and an averaging ADC records them (the layout of ../shared/realdata/akita11, docs/real-data.md):
//
//   device,supply_V,amp_feedback_ohm,temp_C,stroke_mm,pwm_Hz,on_time_s,sample,t_after_edge_s,v_mV_mean,v_mV_sd,repeats
//
// A worked example of the general path: the file becomes valve-runs/2 datasets (gap/dataset.h), one session per
// (device, supply, amplifier, temperature, stroke), one periodic run per (PWM frequency, on-time) with its
// readings, the sense chain declared once. Everything else (identify, diagnose) then works on those datasets.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"

namespace vb::gap {

struct ReadingsCsvOptions {
  double shunt_ohm = 0.2;          // the sense resistor (in the switch's source: in series only while it conducts)
  double amp_ref_ohm = 1000.0;     // non-inverting amplifier: gain = 1 + amp_feedback_ohm / amp_ref_ohm
  double adc_lsb_V = 1e-3;         // the ADC reports whole millivolts
  int averaged = 16;               // PWM periods averaged into one reported reading
  std::string model = "ts98_coil"; // the model the datasets name (a preset, or NAME.json copied beside them)
};

struct ReadingsSession {
  std::string directory;           // the dataset written
  std::string device;
  double supply_V = 0.0, temp_C = 0.0, stroke_m = 0.0;
  int runs = 0, readings = 0;
};

// Reads `csv_path` and writes one dataset directory per session under `out_dir` (created), named
// DEVICE_s<stroke mm>mm_<temp>C. Errors name the file, line and column. Sessions come sorted by device,
// stroke, then temperature.
StatusOr<std::vector<ReadingsSession>> ConvertReadingsCsv(const std::string& csv_path, const std::string& out_dir,
                                                          const ReadingsCsvOptions& options = {});

}  // namespace vb::gap
