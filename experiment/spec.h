// Experiment specs: parse (protobuf JSON), validate (errors name the field path), expand sweeps and repeats,
// and resolve one spec into a runnable Experiment (plant, driver, controller, reference, recording).
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "common/run_key.h"
#include "common/status.h"
#include "control/controller.h"
#include "experiment/metrics.h"
#include "experiment/reference.h"
#include "hw/bench.h"
#include "model/driver.h"
#include "model/params.h"
#include "model/simulator.h"
#include "valvebench/v1/spec.pb.h"

namespace vb::experiment {

using valvebench::v1::ExperimentSpec;

// Parses protobuf JSON (unknown fields are errors: a typo must not silently fall back to a default).
StatusOr<ExperimentSpec> ParseSpecJson(std::string_view json);
StatusOr<ExperimentSpec> LoadSpecFile(const std::string& path);
std::string SpecToJson(const ExperimentSpec& spec, bool pretty = true);

// The bench class a spec asks for: "emulated:<preset>" (the default preset when none is named), or the
// hardware kind ("hid", "u3"). Admission matches runs to benches on it (runs/admit.h); suites check it.
std::string BenchClassOf(const ExperimentSpec& spec);

// Defaults a spec gets when a field is left out (documented in docs/spec.md).
inline constexpr double kDefaultRecordRate_Hz = 50'000.0;
inline constexpr double kDefaultSupply_V = 24.0;

// One run of an expanded spec: the single-run spec (no variants, no sweep, repeats = 1) and its identity.
struct RunPoint {
  ExperimentSpec spec;
  RunKey key;
};
// Expands variants (name "<name>/<variant>"), sweep axes (a full grid, first axis slowest) and repeats into
// single runs. The key carries the sweep point and repeat as fields; the spec also gets the tags
// "sweep:<field>=<value>" and "repeat:<k>" (for people and tag filters; nothing reads them back). The count
// is bounded by max_runs.
StatusOr<std::vector<RunPoint>> ExpandRuns(const ExperimentSpec& spec, size_t max_runs = 100'000);
// The specs of ExpandRuns alone.
StatusOr<std::vector<ExperimentSpec>> ExpandSweep(const ExperimentSpec& spec, size_t max_runs = 100'000);
// Sets a numeric field by path ("conditions.supply_V", "controller.open_loop_pwm.segments[0].duty",
// "bench.model.params[R]").
Status SetFieldByPath(ExperimentSpec* spec, std::string_view path, double value);
StatusOr<double> GetFieldByPath(const ExperimentSpec& spec, std::string_view path);
// A field that holds a number (double, float or an integer): what sweeps and the bounds table act on.
bool IsNumericField(const google::protobuf::FieldDescriptor* f);

// One resolved run.
struct Experiment {
  ExperimentSpec spec;                  // the single-run spec (no sweep)
  model::PlantParams plant;             // preset + overrides + perturbation
  model::DriverParams driver;
  hw::RunConfig run;
  std::unique_ptr<control::Controller> controller;
  ReferenceProfile reference;
  ControlledVariable controlled = ControlledVariable::kNone;
  double duration_s = 0.0;
  double metric_start_s = 0.0, metric_end_s = 0.0;
  double average_window_s = 0.0;        // moving average of x (one PWM period)
  std::vector<double> breakpoints_s;    // where the runner ticks besides the controller period
  model::Disturbance disturbance;       // emulated benches only (perturbation.disturbance_*)
};

// Validates every field (the message names the field path) and builds the run. A spec with sweep axes or
// repeats > 1 is rejected here: expand it first.
StatusOr<Experiment> BuildExperiment(const ExperimentSpec& spec);
// Resolves only the plant (preset, overrides, perturbation): what an emulated bench needs.
StatusOr<model::PlantParams> BuildPlant(const valvebench::v1::ModelSpec& model,
                                        const valvebench::v1::Perturbation* perturbation = nullptr);
StatusOr<model::DriverParams> BuildDriver(const valvebench::v1::DriverSpec& driver);

}  // namespace vb::experiment
