// A stored run as engineers open it: HDF5 (h5py, MATLAB h5read, HDFView) and MATLAB .mat (load, scipy.io).
// Channels carry their SI unit, the run carries its exact spec and operating conditions. One plain struct in,
// one file out: this folder knows nothing of gRPC, the store or benchctl (benchctl/export_files.cc fills it).
//
// HDF5 layout ("valvebench-run/1"):
//   /                      attributes: format, run_id, name, controller, bench, status, reason, spec_json,
//                          t0_s, sample_period_s
//   /channels/<name>       float64 [samples], attribute "units" (t_s: "s", i_A: "A", gate: "1", ...)
//   /conditions/supply_V, /conditions/supply_pressure_Pa   scalar float64, attribute "units"
//   /metrics/<name>        scalar float64, attribute "units"
// Traces of more than 64 Ki samples are chunked and deflate-compressed.
//
// MAT layout (level 5, compressed; MATLAB load() and scipy.io.loadmat read it): one struct variable `vbrun`
//   with fields run_id, name, controller, bench, status, reason, spec_json, t0_s, sample_period_s,
//   channels (struct: one column vector per channel), units (struct: channel -> unit text),
//   conditions (struct: supply_V, supply_pressure_Pa), metrics (struct), metric_units (struct).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "common/status.h"

namespace vb::exportfile {

struct Channel {
  std::string name;  // t_s, gate, v_coil_V, i_A, ... (docs/spec.md recording channels)
  std::string unit;  // SI unit text: "A", "m/s", "1" for dimensionless
  std::vector<double> values;
};

struct Value {
  std::string name;
  double value = 0.0;
  std::string unit;
};

struct RunFile {
  std::int64_t run_id = 0;
  std::string name, controller, bench, status, reason;
  double t0_s = 0.0;
  double sample_period_s = 0.0;
  std::vector<Channel> channels;  // all the same length
  std::string spec_json;          // the exact single-run spec (protobuf JSON)
  std::vector<Value> conditions;  // supply_V, supply_pressure_Pa
  std::vector<Value> metrics;     // finite metrics (docs/metrics.md)
};

// The unit of a trace channel by its name; `ref` takes the controlled variable's unit (A for current laws, m for
// position laws, "" for laws without a reference). Same table as python/valvebench/units.py.
std::string ChannelUnit(const std::string& channel, const std::string& controller);
// The unit of a metric (docs/metrics.md).
std::string MetricUnit(const std::string& metric, const std::string& controller);

// Checks the run (channels of equal length, names usable in both formats); InvalidArgument naming the field.
Status Validate(const RunFile& run);

// Write the file (replacing it). Errors: InvalidArgument from Validate, Unavailable when the file cannot be
// created or written (the message starts with the path).
Status WriteHdf5(const RunFile& run, const std::string& path);
Status WriteMat(const RunFile& run, const std::string& path);

}  // namespace vb::exportfile
