#include "experiment/bounds.h"

#include <cctype>

#include "experiment/spec.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <cmath>
#include <unordered_map>

#include "common/format.h"

namespace vb::experiment {

namespace pb = google::protobuf;
using valvebench::v1::ExperimentSpec;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Times: the longest bench session; every instant in a spec lies inside one run.
constexpr double kMaxDuration_s = 3600.0;
// Currents and positions share the reference fields (A for current laws, m for position laws).
constexpr double kMaxRef = 1000.0;
constexpr double kMaxCurrent_A = 100.0;
constexpr double kMaxCarrier_Hz = 1e6;

constexpr std::string_view kWhyTime = "an instant inside a run, which lasts at most duration_s <= 3600 s";
constexpr std::string_view kWhyCarrier =
    "valve drivers switch at 100 Hz-100 kHz; 1 MHz bounds the PWM edges a run simulates; 0 = the default";
constexpr std::string_view kWhyGain = "a gain this large only amplifies ADC noise; 0 = the default";
constexpr std::string_view kWhyCurrent = "valve coils draw milliamperes to a few amperes";
constexpr std::string_view kWhyRef =
    "the controlled variable: A for current laws (coils draw mA to a few A), m for position laws";
constexpr std::string_view kWhyRohm = "the coil resistance range of model parameter R; 0 = the default";
constexpr std::string_view kWhyLh = "the inductance range of model parameter L; 0 = the default";
constexpr std::string_view kWhyFeedforward = "a coil resistance (model R is at most 1 Mohm); 0 disables";
constexpr std::string_view kWhySwept = "checked against the swept field's own bound when the sweep is expanded";

// clang-format off
constexpr FieldBound kBounds[] = {
  {"duration_s", "s", 0.0, kMaxDuration_s, true, false,
   "the longest bench session (coil-heating runs take minutes); longer is a typo (1e9)"},
  {"repeats", "", 0.0, 10'000.0, false, true, "runs per sweep point for spread statistics; 0 or 1 = once"},
  {"priority", "", -2147483648.0, 2147483647.0, false, false, "queue order only"},
  // bench
  {"bench.model.params[*]", "", -kInf, kInf, false, false,
   "each parameter's own range in the model's table (e.g. R in [0.001, 1e6] ohm), checked when the plant is built"},
  {"bench.model.effects[].params[*]", "", -kInf, kInf, false, false,
   "each effect parameter's own range in the effects table, checked when the plant is built"},
  {"bench.model.inductance_table.stroke_m[]", "m", 0.0, 1.0, false, false, "a valve's stroke is millimetres"},
  {"bench.model.inductance_table.L_H[]", "H", 1e-6, 100.0, false, false, "the range of model parameter L"},
  {"bench.model.identified_driver.params[*]", "", -kInf, kInf, false, false,
   "each driver parameter's own range, checked when the driver is built"},
  {"bench.driver.params[*]", "", -kInf, kInf, false, false,
   "each driver parameter's own range (e.g. diode_drop_V), checked when the driver is built"},
  // conditions
  {"conditions.supply_V", "V", 0.0, 1000.0, true, false,
   "valve coils run at 5-48 V (rectified mains about 325 V); leave it out for the default 24 V"},
  {"conditions.supply_pressure_Pa", "Pa", 0.0, 1e8, false, false, "gauge; hydraulic valves reach 700 bar"},
  // controller
  {"controller.open_loop_pwm.segments[].start_s", "s", 0.0, kMaxDuration_s, false, false, kWhyTime},
  {"controller.open_loop_pwm.segments[].frequency_Hz", "Hz", 0.0, kMaxCarrier_Hz, false, false,
   "valve drivers switch at 100 Hz-100 kHz; 1 MHz bounds the PWM edges a run simulates; 0 = a constant gate"},
  {"controller.open_loop_pwm.segments[].duty", "", 0.0, 1.0, false, false, "a fraction of the period"},
  {"controller.dither_pwm.average_current_A", "A", 0.0, kMaxCurrent_A, false, false, kWhyCurrent},
  {"controller.dither_pwm.dither_amplitude_A", "A", 0.0, kMaxCurrent_A, false, false, kWhyCurrent},
  {"controller.dither_pwm.min_frequency_Hz", "Hz", 1.0, kMaxCarrier_Hz, false, true, kWhyCarrier},
  {"controller.dither_pwm.max_frequency_Hz", "Hz", 1.0, kMaxCarrier_Hz, false, true, kWhyCarrier},
  {"controller.dither_pwm.min_duty", "", 0.0, 1.0, false, true, "a fraction of the period; 0 = the default"},
  {"controller.dither_pwm.max_duty", "", 0.0, 1.0, false, true, "a fraction of the period; 0 = the default"},
  {"controller.dither_pwm.coil_R_ohm", "ohm", 1e-3, 1e6, false, true, kWhyRohm},
  {"controller.dither_pwm.coil_L_H", "H", 1e-6, 100.0, false, true, kWhyLh},
  {"controller.hysteresis_current.band_A", "A", 1e-6, kMaxCurrent_A, false, true,
   "below 1 uA is under any current ADC's step; 0 = the default"},
  {"controller.hysteresis_current.sample_period_s", "s", 1e-7, 1.0, false, true,
   "10 MHz is beyond any bench's current sampling; the period sets the ticks of a run; 0 = the default"},
  {"controller.pi_current.kp_V_per_A", "V/A", 0.0, 1e6, false, true, kWhyGain},
  {"controller.pi_current.ki_V_per_A_s", "V/(A s)", 0.0, 1e9, false, true, kWhyGain},
  {"controller.pi_current.carrier_Hz", "Hz", 1.0, kMaxCarrier_Hz, false, true, kWhyCarrier},
  {"controller.pi_current.feedforward_R_ohm", "ohm", 0.0, 1e6, false, false, kWhyFeedforward},
  {"controller.predictive_current.horizon_s", "s", 1e-7, 1.0, false, true,
   "a prediction horizon between one tick and one second; 0 = the default"},
  {"controller.predictive_current.w_current", "1/A^2", 0.0, 1e12, false, true, "a cost weight; 0 = the default"},
  {"controller.predictive_current.w_voltage", "1/V^2", 0.0, 1e12, false, false, "a cost weight"},
  {"controller.predictive_current.R_ohm", "ohm", 1e-3, 1e6, false, true, kWhyRohm},
  {"controller.predictive_current.L_H", "H", 1e-6, 100.0, false, true, kWhyLh},
  {"controller.predictive_current.carrier_Hz", "Hz", 1.0, kMaxCarrier_Hz, false, true, kWhyCarrier},
  {"controller.fuzzy_current.error_scale_A", "A", 1e-6, kMaxCurrent_A, false, true,
   "a current error scale; 0 = the default"},
  {"controller.fuzzy_current.rate_scale_A_per_s", "A/s", 1e-3, 1e9, false, true,
   "a current slope scale; 0 = the default"},
  {"controller.fuzzy_current.output_scale_V", "V", 1e-3, 1000.0, false, true,
   "an output voltage step, at most the largest supply; 0 = the default"},
  {"controller.fuzzy_current.carrier_Hz", "Hz", 1.0, kMaxCarrier_Hz, false, true, kWhyCarrier},
  {"controller.fuzzy_current.feedforward_R_ohm", "ohm", 0.0, 1e6, false, false, kWhyFeedforward},
  {"controller.cascade_pi_position.kp_position", "N/m", 0.0, 1e12, false, true, kWhyGain},
  {"controller.cascade_pi_position.ki_position", "N/(m s)", 0.0, 1e15, false, true, kWhyGain},
  {"controller.cascade_pi_position.kp_current", "V/A", 0.0, 1e6, false, true, kWhyGain},
  {"controller.cascade_pi_position.ki_current", "V/(A s)", 0.0, 1e9, false, true, kWhyGain},
  {"controller.cascade_pi_position.carrier_Hz", "Hz", 1.0, kMaxCarrier_Hz, false, true, kWhyCarrier},
  {"controller.sliding_mode_position.c_position", "1/s", 0.0, 1e6, false, true, kWhyGain},
  {"controller.sliding_mode_position.k_position", "", 0.0, 1e6, false, true, kWhyGain},
  {"controller.sliding_mode_position.alpha", "", 0.0, 1.0, false, true,
   "a power-rate exponent in (0, 1); 0 = the default"},
  {"controller.sliding_mode_position.k_current", "A/s", 0.0, 1e9, false, true, kWhyGain},
  {"controller.sliding_mode_position.sigmoid_delta", "A", 0.0, kMaxCurrent_A, false, true,
   "a boundary layer in current; 0 = the default"},
  {"controller.sliding_mode_position.carrier_Hz", "Hz", 1.0, kMaxCarrier_Hz, false, true, kWhyCarrier},
  {"controller.peak_and_hold.switching_current_A", "A", 0.0, kMaxCurrent_A, false, true, kWhyCurrent},
  {"controller.peak_and_hold.holding_current_A", "A", 0.0, kMaxCurrent_A, false, true, kWhyCurrent},
  {"controller.peak_and_hold.band_A", "A", 0.0, kMaxCurrent_A, false, true, kWhyCurrent},
  {"controller.peak_and_hold.peak_time_max_s", "s", 0.0, kMaxDuration_s, false, true, kWhyTime},
  // reference
  {"reference.constant.value", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  {"reference.steps.steps[].start_s", "s", 0.0, kMaxDuration_s, false, false, kWhyTime},
  {"reference.steps.steps[].value", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  {"reference.ramp.start_value", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  {"reference.ramp.end_value", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  {"reference.ramp.start_s", "s", 0.0, kMaxDuration_s, false, false, kWhyTime},
  {"reference.ramp.end_s", "s", 0.0, kMaxDuration_s, false, false, kWhyTime},
  {"reference.sine.offset", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  {"reference.sine.amplitude", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  {"reference.sine.frequency_Hz", "Hz", 0.0, 1e5, true, false,
   "a reference a valve can follow is slower than its PWM carrier"},
  {"reference.sine.phase_rad", "rad", -1000.0, 1000.0, false, false, "a phase; a few turns either way"},
  {"reference.on_off_profile.switching_value", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  {"reference.on_off_profile.switching_time_s", "s", 0.0, kMaxDuration_s, false, false, kWhyTime},
  {"reference.on_off_profile.holding_value", "A or m", -kMaxRef, kMaxRef, false, false, kWhyRef},
  // valve command, recording, metrics
  {"valve_command.frequency_Hz", "Hz", 0.0, 1e4, false, false,
   "valves open and close at up to a few hundred Hz; 0 = always on"},
  {"valve_command.duty", "", 0.0, 1.0, false, false, "a fraction of the period"},
  {"recording.rate_Hz", "Hz", 1.0, 1e6, false, true,
   "DAQ benches sample at up to a few hundred kHz; 0 = the default 50 kHz"},
  {"metric_window.start_s", "s", 0.0, kMaxDuration_s, false, false, kWhyTime},
  {"metric_window.end_s", "s", 0.0, kMaxDuration_s, false, false, "an instant inside a run; 0 = the run's end"},
  // sweeps
  {"sweep[].values[]", "", -kInf, kInf, false, false, kWhySwept},
  {"sweep[].grid.start", "", -kInf, kInf, false, false, kWhySwept},
  {"sweep[].grid.stop", "", -kInf, kInf, false, false, kWhySwept},
  {"sweep[].grid.count", "", 1.0, static_cast<double>(kMaxRunsPerSpec), false, false,
   "points of one axis; a spec expands to at most 100000 runs"},
  // perturbation
  {"perturbation.param_scale[*]", "", 0.0, 10.0, true, false,
   "a factor on a model parameter (seed 002 uses 0.75-1.25); the result must still be in the parameter's range"},
  {"perturbation.disturbance_V", "V", -1000.0, 1000.0, false, false,
   "a voltage in series with the coil, on the scale of the supply"},
  {"perturbation.disturbance_Hz", "Hz", 0.0, 1e5, false, false, "0 = constant offsets"},
  {"perturbation.disturbance_force_N", "N", -1e4, 1e4, false, false,
   "valve solenoids and springs exert 1-100 N; seed 002's disturbance is M x 33 N"},
};
// clang-format on

std::string Fmt(double v) { return FormatNumber(v); }  // the one number format for messages

std::string Allowed(const FieldBound& b) {
  std::string range;
  if (std::isinf(b.min) && std::isinf(b.max)) {
    range = "any finite number";
  } else {
    range.assign(1, b.min_open ? '(' : '[');
    range.append(Fmt(b.min)).append(", ").append(Fmt(b.max)).append("]");
    if (!b.unit.empty()) range.append(" ").append(b.unit);
    if (b.zero_is_default) range.append(", or 0");
  }
  std::string out = " (allowed: ";
  out.append(range).append("; ").append(b.why).append(")");
  return out;
}

// `overlay`: a variant, merged over its spec; a 0 there means "not set", whatever the field.
Status CheckValue(const FieldBound* b, const std::string& path, double v, bool overlay) {
  if (!std::isfinite(v))
    return Status::InvalidArgument(path + ": must be a finite number, got " + Fmt(v) + (b ? Allowed(*b) : ""));
  if (b == nullptr || (v == 0.0 && (b->zero_is_default || overlay))) return Status::Ok();
  if (b->min_open ? !(v > b->min) : !(v >= b->min))
    return Status::InvalidArgument(path + ": must be " + (b->min_open ? "> " : ">= ") + Fmt(b->min) + ", got " +
                                   Fmt(v) + Allowed(*b));
  if (!(v <= b->max))
    return Status::InvalidArgument(path + ": must be <= " + Fmt(b->max) + ", got " + Fmt(v) + Allowed(*b));
  return Status::Ok();
}

double ScalarValue(const pb::Message& m, const pb::FieldDescriptor* f, int index) {
  const pb::Reflection* r = m.GetReflection();
  const bool rep = index >= 0;
  switch (f->cpp_type()) {
    case pb::FieldDescriptor::CPPTYPE_DOUBLE: return rep ? r->GetRepeatedDouble(m, f, index) : r->GetDouble(m, f);
    case pb::FieldDescriptor::CPPTYPE_FLOAT: return rep ? r->GetRepeatedFloat(m, f, index) : r->GetFloat(m, f);
    case pb::FieldDescriptor::CPPTYPE_INT32: return rep ? r->GetRepeatedInt32(m, f, index) : r->GetInt32(m, f);
    case pb::FieldDescriptor::CPPTYPE_UINT32: return rep ? r->GetRepeatedUInt32(m, f, index) : r->GetUInt32(m, f);
    case pb::FieldDescriptor::CPPTYPE_INT64:
      return static_cast<double>(rep ? r->GetRepeatedInt64(m, f, index) : r->GetInt64(m, f));
    case pb::FieldDescriptor::CPPTYPE_UINT64:
      return static_cast<double>(rep ? r->GetRepeatedUInt64(m, f, index) : r->GetUInt64(m, f));
    default: return 0.0;
  }
}


std::string Join(const std::string& prefix, const std::string& name) {
  return prefix.empty() ? name : prefix + "." + name;
}

// Walks every number of `m`: `path` is the concrete path ("segments[2]"), `pattern` the table's ("segments[]").
Status Walk(const pb::Message& m, const std::string& path, const std::string& pattern, bool overlay) {
  const pb::Descriptor* d = m.GetDescriptor();
  const pb::Reflection* r = m.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    const std::string fpath = Join(path, f->name());
    const std::string fpattern = Join(pattern, f->name());
    if (f->is_map()) {
      const pb::FieldDescriptor* kf = f->message_type()->map_key();
      const pb::FieldDescriptor* vf = f->message_type()->map_value();
      if (!IsNumericField(vf)) continue;
      const FieldBound* b = FindSpecBound(fpattern + "[*]");
      for (int k = 0; k < r->FieldSize(m, f); ++k) {
        const pb::Message& e = r->GetRepeatedMessage(m, f, k);
        const std::string key = e.GetReflection()->GetString(e, kf);
        VB_RETURN_IF_ERROR(CheckValue(b, fpath + "[" + key + "]", ScalarValue(e, vf, -1), false));
      }
    } else if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
      if (f->is_repeated()) {
        const bool variant = f->message_type() == ExperimentSpec::descriptor();
        for (int k = 0; k < r->FieldSize(m, f); ++k) {
          const std::string at = fpath + "[" + std::to_string(k) + "]";
          // A variant is a spec merged over this one: its paths are a spec's own ("variants[1].duration_s").
          VB_RETURN_IF_ERROR(Walk(r->GetRepeatedMessage(m, f, k), at, variant ? "" : fpattern + "[]", variant || overlay));
        }
      } else if (r->HasField(m, f)) {
        VB_RETURN_IF_ERROR(Walk(r->GetMessage(m, f), fpath, fpattern, overlay));
      }
    } else if (IsNumericField(f)) {
      if (f->is_repeated()) {
        const FieldBound* b = FindSpecBound(fpattern + "[]");
        for (int k = 0; k < r->FieldSize(m, f); ++k)
          VB_RETURN_IF_ERROR(CheckValue(b, fpath + "[" + std::to_string(k) + "]", ScalarValue(m, f, k), false));
      } else if (!f->has_presence() || r->HasField(m, f)) {
        // A proto3 `optional` that is absent takes its default; one that is present is checked, 0 included.
        const FieldBound* b = FindSpecBound(fpattern);
        const bool explicit_zero_counts = f->has_presence();
        const double v = ScalarValue(m, f, -1);
        if (explicit_zero_counts && v == 0.0 && b != nullptr && !overlay) {
          FieldBound strict = *b;
          strict.zero_is_default = false;
          VB_RETURN_IF_ERROR(CheckValue(&strict, fpath, v, false));
        } else {
          VB_RETURN_IF_ERROR(CheckValue(b, fpath, v, overlay));
        }
      }
    }
  }
  return Status::Ok();
}

std::uint64_t MulSat(std::uint64_t a, std::uint64_t b) {
  std::uint64_t out = 0;
  return __builtin_mul_overflow(a, b, &out) ? UINT64_MAX : out;
}
std::uint64_t AddSat(std::uint64_t a, std::uint64_t b) {
  std::uint64_t out = 0;
  return __builtin_add_overflow(a, b, &out) ? UINT64_MAX : out;
}

std::uint64_t AxisPoints(const valvebench::v1::SweepAxis& ax) {
  return static_cast<std::uint64_t>(ax.values_size()) + (ax.has_grid() ? ax.grid().count() : 0u);
}

// Runs of one spec without variants, with `extra` axes appended (a variant's, merged over its base).
std::uint64_t CountOne(const ExperimentSpec& spec, const ExperimentSpec* overlay) {
  std::uint32_t repeats = spec.repeats();
  if (overlay != nullptr && overlay->repeats() != 0) repeats = overlay->repeats();
  std::uint64_t total = repeats == 0 ? 1 : repeats;
  for (const auto& ax : spec.sweep()) total = MulSat(total, AxisPoints(ax));
  if (overlay != nullptr)
    for (const auto& ax : overlay->sweep()) total = MulSat(total, AxisPoints(ax));
  return total;
}

}  // namespace

std::span<const FieldBound> SpecBounds() { return kBounds; }

const FieldBound* FindSpecBound(std::string_view pattern) {
  static const auto* index = [] {
    auto* m = new std::unordered_map<std::string_view, const FieldBound*>();
    for (const FieldBound& b : kBounds) m->emplace(b.path, &b);
    return m;
  }();
  const auto it = index->find(pattern);
  return it == index->end() ? nullptr : it->second;
}

Status CheckFieldValue(std::string_view path, double value) {
  // The table's pattern of a concrete path: indices become "[]" (map keys stay: a map's pattern is "[*]").
  std::string pattern;
  for (std::size_t k = 0; k < path.size(); ++k) {
    if (path[k] == '[' && k + 1 < path.size() && std::isdigit(static_cast<unsigned char>(path[k + 1]))) {
      const std::size_t close = path.find(']', k);
      if (close == std::string_view::npos) break;
      pattern += "[]";
      k = close;
    } else {
      pattern += path[k];
    }
  }
  return CheckValue(FindSpecBound(pattern), std::string(path), value, false);
}

std::uint64_t CountRuns(const ExperimentSpec& spec) {
  if (spec.variants_size() == 0) return CountOne(spec, nullptr);
  std::uint64_t total = 0;
  for (const auto& v : spec.variants()) total = AddSat(total, CountOne(spec, &v));
  return total;
}

Status CheckSpecBounds(const ExperimentSpec& spec) {
  VB_RETURN_IF_ERROR(Walk(spec, "", "", false));
  const std::uint64_t runs = CountRuns(spec);
  if (runs > kMaxRunsPerSpec)
    return Status::InvalidArgument(
        "sweep: the spec expands to " + (runs == UINT64_MAX ? std::string("more than 1.8e19") : std::to_string(runs)) +
        " runs (variants x sweep points x repeats), more than " + std::to_string(kMaxRunsPerSpec));
  const double cycles = spec.duration_s() * spec.valve_command().frequency_hz();
  if (cycles > kMaxValveCommandCycles)
    return Status::InvalidArgument("valve_command.frequency_Hz: " + Fmt(spec.valve_command().frequency_hz()) +
                                   " Hz over duration_s = " + Fmt(spec.duration_s()) + " s is " + Fmt(cycles) +
                                   " on/off cycles, more than " + Fmt(kMaxValveCommandCycles));
  return Status::Ok();
}

}  // namespace vb::experiment
