// Physical bounds of every number an experiment spec carries: one table (field path, unit, range, why),
// checked in one place (CheckSpecBounds), before anything is expanded, allocated or simulated. docs/spec.md
// prints the table. Finer, cross-field checks (segments in order, metric window inside the run, a law's own
// consistency) stay where they are; this layer makes sure no number is absurd, infinite or NaN first.
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>

#include "common/status.h"
#include "valvebench/v1/spec.pb.h"

namespace vb::experiment {

// One field's bound. Paths use the proto field names; "[]" stands for any index of a repeated field, "[*]" for
// any key of a map ("controller.open_loop_pwm.segments[].duty", "bench.model.params[*]").
struct FieldBound {
  std::string_view path;
  std::string_view unit;          // SI unit of the field ("" for a plain number)
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_open = false;          // the range excludes min ("(0, 1000]")
  bool zero_is_default = false;   // 0 is proto3's "not set": the documented default, always accepted
  std::string_view why;
};

// The table, in spec order. Every numeric field of ExperimentSpec has exactly one entry (a test checks it).
std::span<const FieldBound> SpecBounds();
// The entry for a path pattern ("conditions.supply_V", "sweep[].grid.count"), or nullptr.
const FieldBound* FindSpecBound(std::string_view pattern);

// The most runs one spec may expand to (variants x sweep points x repeats), whatever the caller's own limit.
inline constexpr std::uint64_t kMaxRunsPerSpec = 100'000;
// The most on/off cycles of the valve command one run may schedule (duration_s x valve_command.frequency_Hz).
inline constexpr double kMaxValveCommandCycles = 1e6;

// Checks every number of `spec` (variants included) against SpecBounds(): no NaN or infinity anywhere (map
// values too), every value in its range. The first violation is InvalidArgument naming the field path, the
// value, the range with its unit and why, e.g.
//   "conditions.supply_V: must be > 0, got 0 (allowed: (0, 1000] V; ...)"
//   "variants[1].perturbation.disturbance_force_N: must be >= -10000, got -1e+308 (allowed: ...)".
// Also the cross-field counts: the runs the spec expands to (CountRuns) and the valve command's cycles.
Status CheckSpecBounds(const valvebench::v1::ExperimentSpec& spec);

// Checks one value against the entry of a concrete field path ("controller.open_loop_pwm.segments[0].duty").
// A path with no entry only has to be finite.
Status CheckFieldValue(std::string_view path, double value);

// The runs a spec expands to: the sum over its variants (or the spec itself) of repeats x the product of its
// sweep axes' point counts. Saturates at UINT64_MAX instead of overflowing.
std::uint64_t CountRuns(const valvebench::v1::ExperimentSpec& spec);

}  // namespace vb::experiment
