// Importer for measured-run datasets: measured valve runs to compare with a model (the sim-to-real gap).
// A dataset is a directory with manifest.json and the files it names; docs/dataset-format.md gives both formats
// as accepted here, every validation rule and its error message.
//   valve-runs/1: dense waveforms from rest on a uniform grid with the gate command (the gapbench format).
//   valve-runs/2: what benches actually record: dense waveforms, samples at arbitrary instants, and periodic
//                 steady-state readings (mean and spread over repeats at fixed delays after the PWM's rising
//                 edge); per run the temperature and a held stroke; per dataset the sense chain and the driver.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"
#include "common/split.h"
#include "model/driver.h"

namespace vb::gap {

inline constexpr std::string_view kFormatValveRuns1 = "valve-runs/1";
inline constexpr std::string_view kFormatValveRuns2 = "valve-runs/2";
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// What a run holds.
enum class RunKind : std::uint8_t {
  kWaveform,  // dense samples on a uniform grid with the gate command per sample (valve-runs/1's only kind)
  kSamples,   // current samples at arbitrary instants; the gate command as a list of edge times
  kPeriodic,  // PWM held until the current is periodic; readings at fixed delays after the rising edge
};
std::string_view RunKindName(RunKind k);

// One run: the manifest entry and its measurements. i_A holds every measured value of the run (one per
// sample or reading), t_s their instants: from the run's start (waveform, samples) or after the PWM's rising
// edge (periodic).
struct RunData {
  std::string id;
  std::string file;                     // as written in the manifest, relative to the dataset directory ("" for
                                        // periodic runs, whose readings are in the manifest)
  RunKind kind = RunKind::kWaveform;
  double supply_V = 0.0;                // > 0: the supply as measured
  double supply_pressure_Pa = 0.0;      // >= 0
  double t_start_s = 0.0;               // >= 0, seconds since the bench was powered; NaN: not recorded
  Split split = Split::kNone;           // the manifest's (common/split.h); kNone if absent
  // Covariates (NaN: not recorded).
  double ambient_C = kNaN;              // the air (chamber) temperature
  double coil_C = kNaN;                 // the winding temperature
  double stroke_m = kNaN;               // the plunger is held at this stroke for the whole run
  bool from_rest = true;                // waveform: the current starts at 0 (else at the first sample's value)
  // kWaveform
  double sample_period_s = 0.0;         // (t_s.back() - t_s.front()) / (samples - 1)
  std::vector<int8_t> gate;             // 0 or 1, per sample
  std::vector<double> x_m;              // empty if the column is absent
  std::vector<double> v_coil_V;         // empty if the column is absent
  // kSamples: the gate is 0 before gate_edges_s[0] and toggles at every edge.
  std::vector<double> gate_edges_s;
  // kPeriodic
  double pwm_Hz = 0.0;
  double on_time_s = 0.0;
  // Every kind.
  std::vector<double> t_s;              // waveform: from 0, uniform; samples: increasing; periodic: after the edge
  std::vector<double> i_A;              // measured (a reading's mean over its repeats)
  std::vector<double> i_sd_A;           // spread over repeats (sample standard deviation); empty: not given
  std::vector<int> repeats;             // repeats behind each reading; empty: 1 each

  // The temperature that best describes the winding: coil_C, else ambient_C, else NaN.
  double temperature_C() const { return std::isfinite(coil_C) ? coil_C : ambient_C; }
};

// The current-sense chain as the dataset declares it (valve-runs/2 "sensor"; NaN: not declared).
struct SensorChain {
  double shunt_ohm = kNaN;              // sense resistor
  bool shunt_in_switch_path = false;    // a low-side source shunt: in series with the coil only while the
                                        // switch conducts (the model adds it as supply resistance)
  double amplifier_gain = kNaN;         // V/V between the shunt and the ADC
  double adc_lsb_V = kNaN;              // the ADC's step, at its input
  double adc_lsb_A = kNaN;              // the step in amperes (given, or adc_lsb_V / (shunt_ohm x gain))
  double noise_A = kNaN;                // white noise of one raw reading
  double offset_A = 0.0;                // a known offset of the readings (the model starts from it)
  int averaged = 1;                     // raw readings averaged into one reported reading
};

struct Dataset {
  std::string format;                   // "valve-runs/1" or "valve-runs/2"
  std::string model;                    // one of the known model names, or (valve-runs/2) a model file
  std::string model_file;               // the model file's path (directory / model) when model names a file
  std::string device;                   // valve-runs/2: the device's name ("" if absent)
  SensorChain sensor;                   // valve-runs/2: the sense chain (defaults: nothing declared)
  model::DriverParams driver;           // valve-runs/2: the bench's driver (default: low-side with flyback diode)
  std::string description;              // "" if absent
  std::string directory;                // as passed to LoadDataset
  std::vector<RunData> runs;            // in manifest order (= time order)
  // What was ignored: unknown CSV columns, unknown manifest keys. Each names the file (and the run).
  std::vector<std::string> warnings;
};

// The model names accepted when the caller passes none: {"taghizadeh2009"}. Callers that know the model
// presets pass them instead (e.g. model::PresetNames()).
std::vector<std::string> DefaultKnownModels();

// White-noise sigma of a densely sampled current from its second differences, sqrt(mean(d2^2) / 6): the
// smooth coil current barely contributes at 50 kHz. Between the gate's edges only: see the overload below.
double SecondDifferenceSigma(const std::vector<double>& i);

// The same, leaving out the second differences within kNoiseEdgeGuard_s (and at least two samples) of a gate
// edge. An edge is a step of the coil's voltage: the current's slope jumps there by V / L and, with an eddy
// path or a switching spike, the current itself, so one second difference at a 50 kHz switch-on edge can be
// 100x the noise, and a 10 ms capture has only one edge to average it over (practice4's p41_1: 3.0 mA from all
// samples, 0.46 mA between the edges, against 0.46 mA its chain declares). The guard spans the eddy rungs'
// decay (20-40 us on practice4's valves). When the guard would leave fewer than half the samples (a PWM
// waveform sampled a few times per period), every sample is used, as the first form does.
inline constexpr double kNoiseEdgeGuard_s = 50e-6;
double SecondDifferenceSigma(const std::vector<double>& i, const std::vector<int8_t>& gate, double sample_period_s);

// The standard error of each measured value from what the dataset says: a reading's spread over its repeats,
// the ADC step and the declared noise (per raw reading, divided by averaging and repeats). Empty when the
// dataset says nothing of its noise (waveforms estimate it from the data instead).
std::vector<double> DeclaredStandardErrors(const Dataset& ds, const RunData& run);

// Loads and validates a dataset directory. Every violation is InvalidArgument with a message that starts with
// the file ("<dataset>/manifest.json: runs[3].split: ...", "<dataset>/<file>.csv:1234: column i_A: ..."), where
// <dataset> is the last component of `directory`.
StatusOr<Dataset> LoadDataset(const std::string& directory,
                              const std::vector<std::string>& known_models = DefaultKnownModels());

// The same from files held in memory (file name -> contents: "manifest.json" and the files it names), for a
// dataset that arrives over the network (the web's upload): the same checks and messages, "<name>/..." in
// them; no file is written. Dataset::directory stays empty and model_file holds the model file's name.
StatusOr<Dataset> LoadDatasetFromFiles(const std::string& name, const std::map<std::string, std::string>& files,
                                       const std::vector<std::string>& known_models = DefaultKnownModels());

}  // namespace vb::gap
