// The physical bounds of a spec (experiment/bounds.h): one table, every number checked, field-named errors,
// run counts without overflow. Each defect of issue 14 that the table fixes has its test here.
#include <gtest/gtest.h>

#include <google/protobuf/descriptor.h>

#include <cctype>
#include <cstdint>
#include <fstream>
#include <set>
#include <sstream>

#include "experiment/bounds.h"
#include "experiment/spec.h"
#include "experiment/trace.h"

namespace vb::experiment {
namespace {

namespace pb = google::protobuf;

constexpr const char* kPwm =
    R"("controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.4}]}})";
constexpr const char* kPi = R"("controller": {"pi_current": {}})";

ExperimentSpec Parse(const std::string& json) {
  auto spec = ParseSpecJson(json);
  EXPECT_TRUE(spec.ok()) << json << ": " << spec.status().message();
  return spec.ok() ? *spec : ExperimentSpec();
}

// Builds the spec (expanding it first when it has sweeps, repeats or variants) and returns the first error.
Status Admit(const std::string& json) {
  ExperimentSpec spec = Parse(json);
  auto runs = ExpandSweep(spec);
  if (!runs.ok()) return runs.status();
  for (const auto& r : *runs) {
    auto e = BuildExperiment(r);
    if (!e.ok()) return e.status();
  }
  return Status::Ok();
}

void ExpectRefused(const std::string& json, const std::string& expected_start) {
  const Status st = Admit(json);
  ASSERT_FALSE(st.ok()) << json;
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << st.message();
  EXPECT_EQ(st.message().rfind(expected_start, 0), 0u)
      << "message '" << st.message() << "' should start with '" << expected_start << "'";
}

// Every numeric field path of a message type, in the table's pattern form.
void NumericPaths(const pb::Descriptor* d, const std::string& prefix, std::set<std::string>* out, int depth = 0) {
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    const std::string path = prefix.empty() ? f->name() : prefix + "." + f->name();
    if (f->is_map()) {
      if (f->message_type()->map_value()->cpp_type() != pb::FieldDescriptor::CPPTYPE_STRING) out->insert(path + "[*]");
    } else if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
      if (f->message_type() == ExperimentSpec::descriptor()) continue;  // variants: a spec's own paths
      if (depth < 8) NumericPaths(f->message_type(), f->is_repeated() ? path + "[]" : path, out, depth + 1);
    } else if (f->cpp_type() != pb::FieldDescriptor::CPPTYPE_STRING &&
               f->cpp_type() != pb::FieldDescriptor::CPPTYPE_BOOL && f->cpp_type() != pb::FieldDescriptor::CPPTYPE_ENUM) {
      out->insert(f->is_repeated() ? path + "[]" : path);
    }
  }
}

TEST(SpecBounds, TheTableCoversEveryNumberOfTheSpecAndNothingElse) {
  std::set<std::string> fields;
  NumericPaths(ExperimentSpec::descriptor(), "", &fields);
  std::set<std::string> table;
  for (const FieldBound& b : SpecBounds()) {
    EXPECT_TRUE(table.insert(std::string(b.path)).second) << "twice in the table: " << b.path;
    EXPECT_FALSE(b.why.empty()) << b.path;
    EXPECT_LE(b.min, b.max) << b.path;
  }
  for (const auto& f : fields) EXPECT_TRUE(table.count(f)) << "no bound for " << f;
  for (const auto& t : table) EXPECT_TRUE(fields.count(t)) << "the table names no field of the spec: " << t;
}

TEST(SpecBounds, TheExamplesAreInside) {
  for (const char* name : {"standard/e1.json", "standard/e2.json", "standard/e3.json", "dither.json",
                           "static-map.json", "compare-current-controllers.json",
                           "compare-position-controllers.json"}) {
    auto spec = LoadSpecFile(std::string(VB_SOURCE_DIR) + "/examples/" + name);
    ASSERT_TRUE(spec.ok()) << name << ": " << spec.status().message();
    EXPECT_TRUE(CheckSpecBounds(*spec).ok()) << name << ": " << CheckSpecBounds(*spec).message();
  }
}

// Issue 14: a NaN reference was accepted and the run ended DONE with every metric 0.
TEST(SpecBounds, NanReferenceIsRefused) {
  ExpectRefused(R"({"duration_s": 0.01, "reference": {"constant": {"value": "NaN"}}, )" + std::string(kPi) + "}",
                "reference.constant.value: must be a finite number, got nan (allowed: [-1000, 1000] A or m");
  ExpectRefused(R"({"duration_s": 0.01, "reference": {"steps": {"steps": [{"start_s": 0, "value": 0.1},
                   {"start_s": 0.005, "value": "-Infinity"}]}}, )" + std::string(kPi) + "}",
                "reference.steps.steps[1].value: must be a finite number, got -inf");
}

// Issue 14: `duration_s: 1e9` was refused naming recording.rate_Hz.
TEST(SpecBounds, HugeDurationNamesDuration) {
  ExpectRefused(R"({"duration_s": 1e9, )" + std::string(kPwm) + "}",
                "duration_s: must be <= 3600, got 1000000000 (allowed: (0, 3600] s;");
  // Inside the bound but too many samples at the recording rate: the message still starts with duration_s.
  const Status st = Admit(R"({"duration_s": 3600, )" + std::string(kPwm) + "}");
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.message().rfind("duration_s: 3600 s at recording.rate_Hz = 50000 Hz is 180000000 samples", 0), 0u)
      << st.message();
}

// Issue 14: `supply_V: 0` was accepted (silently run at 24 V) though the proto says > 0.
TEST(SpecBounds, ExplicitZeroSupplyIsRefusedAbsentSupplyIsTheDefault) {
  ExpectRefused(R"({"duration_s": 0.01, "conditions": {"supply_V": 0}, )" + std::string(kPwm) + "}",
                "conditions.supply_V: must be > 0, got 0 (allowed: (0, 1000] V;");
  ExpectRefused(R"({"duration_s": 0.01, "conditions": {"supply_V": 1e6}, )" + std::string(kPwm) + "}",
                "conditions.supply_V: must be <= 1000, got 1000000");
  auto e = BuildExperiment(Parse(R"({"duration_s": 0.01, "conditions": {"supply_pressure_Pa": 1e5}, )" +
                                 std::string(kPwm) + "}"));
  ASSERT_TRUE(e.ok()) << e.status().message();
  EXPECT_EQ(e->run.supply_V, kDefaultSupply_V);
}

// Issue 14: `perturbation.disturbance_force_N = -1e308` passed validation and the run stalled.
TEST(SpecBounds, AbsurdDisturbanceIsRefused) {
  ExpectRefused(R"({"duration_s": 0.01, "perturbation": {"disturbance_force_N": -1e308}, )" + std::string(kPwm) + "}",
                "perturbation.disturbance_force_N: must be >= -10000, got -1e+308 (allowed: [-10000, 10000] N;");
  ExpectRefused(R"({"duration_s": 0.01, "perturbation": {"param_scale": {"R": 1e300}}, )" + std::string(kPwm) + "}",
                "perturbation.param_scale[R]: must be <= 10, got 1e+300");
}

// Issue 14: `repeats: 4294967295` escaped as UNKNOWN from the server and aborted `run --local`.
TEST(SpecBounds, HugeRepeatsAreRefusedBeforeAnyAllocation) {
  ExpectRefused(R"({"duration_s": 0.01, "repeats": 4294967295, )" + std::string(kPwm) + "}",
                "repeats: must be <= 10000, got 4294967295");
  // Variants are specs too: their numbers are named with their index.
  ExpectRefused(R"({"duration_s": 0.01, )" + std::string(kPwm) + R"(, "variants": [{"name": "a"},
                   {"name": "b", "repeats": 4294967295}]})",
                "variants[1].repeats: must be <= 10000, got 4294967295");
}

TEST(SpecBounds, RunCountsSaturateInsteadOfOverflowing) {
  // 10000 repeats x 4294967295^3 grid points overflows 64 bits many times over.
  ExperimentSpec spec = Parse(R"({"duration_s": 0.01, "repeats": 10000, )" + std::string(kPwm) + R"(, "sweep": [
      {"field": "conditions.supply_V", "grid": {"start": 1, "stop": 2, "count": 4294967295}},
      {"field": "conditions.supply_pressure_Pa", "grid": {"start": 0, "stop": 1, "count": 4294967295}},
      {"field": "perturbation.disturbance_V", "grid": {"start": 0, "stop": 1, "count": 4294967295}}]})");
  EXPECT_EQ(CountRuns(spec), UINT64_MAX);
  // Each axis alone is bounded by the table...
  auto runs = ExpandSweep(spec);
  ASSERT_FALSE(runs.ok());
  EXPECT_EQ(runs.status().message().rfind("sweep[0].grid.count: must be <= 100000, got 4294967295", 0), 0u)
      << runs.status().message();
  // ... and the product of axes that are each fine, times repeats and variants, by the count.
  spec = Parse(R"({"duration_s": 0.01, "repeats": 1000, )" + std::string(kPwm) + R"(, "sweep": [
      {"field": "conditions.supply_V", "grid": {"start": 1, "stop": 2, "count": 100000}},
      {"field": "conditions.supply_pressure_Pa", "grid": {"start": 0, "stop": 1, "count": 100000}}],
      "variants": [{"name": "a"}, {"name": "b"}, {"name": "c"}]})");
  EXPECT_EQ(CountRuns(spec), 3ull * 1000 * 100000 * 100000);
  runs = ExpandSweep(spec);
  ASSERT_FALSE(runs.ok());
  EXPECT_EQ(runs.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(runs.status().message(),
            "sweep: the spec expands to 30000000000000 runs (variants x sweep points x repeats), more than 100000");
  // A caller's smaller limit stays a resource limit.
  spec = Parse(R"({"duration_s": 0.01, "repeats": 50, )" + std::string(kPwm) + "}");
  runs = ExpandSweep(spec, 10);
  ASSERT_FALSE(runs.ok());
  EXPECT_EQ(runs.status().code(), StatusCode::kResourceExhausted) << runs.status().message();
}

TEST(SpecBounds, SweptValuesAreCheckedAgainstTheSweptField) {
  ExpectRefused(R"({"duration_s": 0.01, )" + std::string(kPwm) +
                    R"(, "sweep": [{"field": "conditions.supply_V", "values": [12, 24, -1]}]})",
                "sweep[0].values[2]: conditions.supply_V: must be > 0, got -1");
  ExpectRefused(R"({"duration_s": 0.01, )" + std::string(kPwm) +
                    R"(, "sweep": [{"field": "controller.open_loop_pwm.segments[0].duty",
                                    "grid": {"start": 0, "stop": 2, "count": 5}}]})",
                "sweep[0].grid.stop: controller.open_loop_pwm.segments[0].duty: must be <= 1, got 2");
  // An integer field takes whole values of its range only (the cast was undefined before).
  ExpectRefused(R"({"duration_s": 0.01, )" + std::string(kPwm) +
                    R"(, "sweep": [{"field": "priority", "values": [1e20]}]})",
                "sweep[0].field: field path 'priority': 1e+20 is not a whole number");
  // An index too large for int was an uncaught std::out_of_range (std::stoi).
  ExpectRefused(R"({"duration_s": 0.01, )" + std::string(kPwm) +
                    R"(, "sweep": [{"field": "controller.open_loop_pwm.segments[99999999999].duty", "values": [0.5]}]})",
                "sweep[0].field: field path 'controller.open_loop_pwm.segments[99999999999].duty': index 99999999999 "
                "is too large");
}

TEST(SpecBounds, ValveCommandCyclesAreBounded) {
  ExpectRefused(R"({"duration_s": 1000, "recording": {"rate_Hz": 1000}, "valve_command": {"frequency_Hz": 5000,
                   "duty": 0.5}, "reference": {"constant": {"value": 0.1}}, )" + std::string(kPi) + "}",
                "valve_command.frequency_Hz: 5000 Hz over duration_s = 1000 s is 5000000 on/off cycles, more than 1000000");
}

TEST(SpecBounds, ZeroInAVariantMeansNotSet) {
  // A variant overlays only what it sets: its duration_s of 0 is the base's duration, not an error.
  EXPECT_TRUE(Admit(R"({"duration_s": 0.01, )" + std::string(kPwm) + R"(, "variants": [{"name": "a",
                       "conditions": {"supply_V": 12}}, {"name": "b"}]})").ok());
}

// Issue 14: the proto listed 9 default trace channels; the trace records 12.
TEST(SpecBounds, TheProtoListsEveryDefaultChannel) {
  std::ifstream in(std::string(VB_SOURCE_DIR) + "/proto/valvebench/v1/spec.proto");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string proto = ss.str();
  const size_t at = proto.find("message RecordingSpec");
  ASSERT_NE(at, std::string::npos);
  const std::string recording = proto.substr(at, proto.find('}', at) - at);
  auto lists = [&](const std::string& name) {  // as a whole word
    for (size_t k = recording.find(name); k != std::string::npos; k = recording.find(name, k + 1)) {
      const char after = k + name.size() < recording.size() ? recording[k + name.size()] : ' ';
      const char before = k > 0 ? recording[k - 1] : ' ';
      if (!std::isalnum(static_cast<unsigned char>(after)) && after != '_' &&
          !std::isalnum(static_cast<unsigned char>(before)) && before != '_')
        return true;
    }
    return false;
  };
  for (const auto& name : Trace::ChannelNames())
    EXPECT_TRUE(lists(name)) << "RecordingSpec's comment does not list " << name;
}

}  // namespace
}  // namespace vb::experiment
