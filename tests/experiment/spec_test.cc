#include <gtest/gtest.h>

#include "experiment/spec.h"

namespace vb::experiment {
namespace {

std::string Example(const std::string& rel) { return std::string(VB_SOURCE_DIR) + "/examples/" + rel; }

TEST(Spec, StandardExamplesParseAndBuild) {
  for (const char* name : {"standard/e1.json", "standard/e2.json", "standard/e3.json"}) {
    auto spec = LoadSpecFile(Example(name));
    ASSERT_TRUE(spec.ok()) << name << ": " << spec.status().message();
    auto e = BuildExperiment(*spec);
    ASSERT_TRUE(e.ok()) << name << ": " << e.status().message();
    EXPECT_EQ(e->run.sample_rate_Hz, 50000.0);
  }
}

Status BuildError(const std::string& json) {
  auto spec = ParseSpecJson(json);
  if (!spec.ok()) return spec.status();
  auto e = BuildExperiment(*spec);
  return e.ok() ? Status::Ok() : e.status();
}

void ExpectErrorNames(const std::string& json, const std::string& field) {
  Status st = BuildError(json);
  ASSERT_FALSE(st.ok()) << json;
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << st.message();
  EXPECT_NE(st.message().find(field), std::string::npos) << "message '" << st.message() << "' should name " << field;
}

constexpr const char* kPwm = R"("controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.4}]}})";

TEST(Spec, BadInputNamesTheField) {
  const std::string pwm = kPwm;
  ExpectErrorNames(R"({"duration_s": 0, )" + pwm + "}", "duration_s");
  ExpectErrorNames(R"({"duration_s": 1, "conditions": {"supply_V": -3}, )" + pwm + "}", "conditions.supply_V");
  ExpectErrorNames(R"({"duration_s": 1, "conditions": {"supply_pressure_Pa": -1}, )" + pwm + "}",
                   "conditions.supply_pressure_Pa");
  ExpectErrorNames(R"({"duration_s": 1, "bench": {"model": {"preset": "foo"}}, )" + pwm + "}", "bench.model.preset");
  ExpectErrorNames(R"({"duration_s": 1, "bench": {"model": {"params": {"R": -1}}}, )" + pwm + "}",
                   "bench.model.params[R]");
  ExpectErrorNames(R"({"duration_s": 1, "bench": {"model": {"params": {"Rx": 1}}}, )" + pwm + "}", "Rx");
  ExpectErrorNames(R"({"duration_s": 1, "bench": {"driver": {"kind": "triac"}}, )" + pwm + "}", "bench.driver.kind");
  ExpectErrorNames(
      R"({"duration_s": 1, "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 1.5}]}}})",
      "controller.open_loop_pwm.segments[0].duty");
  ExpectErrorNames(
      R"({"duration_s": 1, "controller": {"open_loop_pwm": {"segments": [{"start_s": 0.1, "frequency_Hz": 50, "duty": 0.5}]}}})",
      "segments[0].start_s");
  ExpectErrorNames(R"({"duration_s": 1})", "controller");
  ExpectErrorNames(R"({"duration_s": 1, "recording": {"rate_Hz": -5}, )" + pwm + "}", "recording.rate_Hz");
  ExpectErrorNames(R"({"duration_s": 1, "recording": {"channels": ["i_A", "bogus"]}, )" + pwm + "}",
                   "recording.channels[1]");
  ExpectErrorNames(R"({"duration_s": 1, "metric_window": {"start_s": 2}, )" + pwm + "}", "metric_window");
  // JSON-level problems: protobuf names the field.
  ExpectErrorNames(R"({"duration_s": "abc", )" + pwm + "}", "duration_s");
  ExpectErrorNames(R"({"durration_s": 1, )" + pwm + "}", "durration_s");
}

TEST(Sweep, GridTimesRepeatsWithTags) {
  auto spec = ParseSpecJson(std::string(R"({"name": "s", "duration_s": 0.1, "repeats": 2, )") + kPwm +
                            R"(, "sweep": [{"field": "controller.open_loop_pwm.segments[0].duty", "grid": {"start": 0.1, "stop": 0.9, "count": 5}},
                                           {"field": "conditions.supply_pressure_Pa", "values": [0, 400000]}]})");
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  auto runs = ExpandSweep(*spec);
  ASSERT_TRUE(runs.ok()) << runs.status().message();
  ASSERT_EQ(runs->size(), 5u * 2u * 2u);
  EXPECT_DOUBLE_EQ((*runs)[0].controller().open_loop_pwm().segments(0).duty(), 0.1);
  EXPECT_DOUBLE_EQ((*runs)[19].controller().open_loop_pwm().segments(0).duty(), 0.9);
  EXPECT_DOUBLE_EQ((*runs)[2].conditions().supply_pressure_pa(), 400000.0);
  for (const auto& r : *runs) {
    EXPECT_EQ(r.sweep_size(), 0);
    EXPECT_TRUE(BuildExperiment(r).ok());
  }
}

TEST(Sweep, MapEntriesAndBadPaths) {
  auto spec = ParseSpecJson(std::string(R"({"duration_s": 0.1, )") + kPwm +
                            R"(, "sweep": [{"field": "bench.model.params[R]", "values": [12, 14]}]})");
  ASSERT_TRUE(spec.ok());
  auto runs = ExpandSweep(*spec);
  ASSERT_TRUE(runs.ok()) << runs.status().message();
  auto e = BuildExperiment((*runs)[1]);
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->plant.R_ohm, 14.0);

  auto bad = ParseSpecJson(std::string(R"({"duration_s": 0.1, )") + kPwm +
                           R"(, "sweep": [{"field": "conditions.supply_volts", "values": [1]}]})");
  ASSERT_TRUE(bad.ok());
  auto st = ExpandSweep(*bad);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.status().message().find("sweep[0].field"), std::string::npos) << st.status().message();
  EXPECT_NE(st.status().message().find("supply_volts"), std::string::npos);
}

TEST(Perturbation, ScalesModelParameters) {
  auto spec = ParseSpecJson(std::string(R"({"duration_s": 0.1, )") + kPwm +
                            R"(, "perturbation": {"param_scale": {"R": 1.25, "k": 0.75}}})");
  ASSERT_TRUE(spec.ok());
  auto e = BuildExperiment(*spec);
  ASSERT_TRUE(e.ok()) << e.status().message();
  EXPECT_DOUBLE_EQ(e->plant.R_ohm, 13.0 * 1.25);
  EXPECT_DOUBLE_EQ(e->plant.k_N_per_m, 1e4 * 0.75);
}

}  // namespace
}  // namespace vb::experiment

namespace vb::experiment {
namespace {

// A law's own parameter errors are reported at the spec's field path, the one the user wrote.
TEST(Spec, ControllerErrorsNameTheSpecField) {
  const std::string coil = R"("bench": {"model": {"preset": "ts98_coil"}}, "reference": {"constant": {"value": 0.5}})";
  const std::string lunge = R"("bench": {"model": {"preset": "lunge2013"}}, "conditions": {"supply_V": 230},
                               "reference": {"constant": {"value": 0.001}})";
  const std::pair<std::string, std::string> cases[] = {
      {coil + R"(, "controller": {"hysteresis_current": {"band_A": -1}})", "controller.hysteresis_current.band_A"},
      {coil + R"(, "controller": {"pi_current": {"carrier_Hz": -5}})", "controller.pi_current.carrier_Hz"},
      {coil + R"(, "controller": {"hysteresis_current": {"sample_period_s": -1}})",
       "controller.hysteresis_current.sample_period_s"},
      {coil + R"(, "controller": {"pi_current": {"ki_V_per_A_s": -1}})", "controller.pi_current.ki_V_per_A_s"},
      {coil + R"(, "controller": {"fuzzy_current": {"output_scale_V": -1}})", "controller.fuzzy_current.output_scale_V"},
      {coil + R"(, "controller": {"predictive_current": {"horizon_s": -1}})", "controller.predictive_current.horizon_s"},
      {coil + R"(, "controller": {"fuzzy_current": {"error_scale_A": -1}})", "controller.fuzzy_current.error_scale_A"},
      {coil + R"(, "controller": {"peak_and_hold": {"holding_current_A": -1}})",
       "controller.peak_and_hold.holding_current_A"},
      {coil + R"(, "controller": {"dither_pwm": {"average_current_A": 0.1, "dither_amplitude_A": 0.2}})",
       "controller.dither_pwm.dither_amplitude_A"},
      {lunge + R"(, "controller": {"cascade_pi_position": {"kp_position": -1}})",
       "controller.cascade_pi_position.kp_position"},
      {lunge + R"(, "controller": {"sliding_mode_position": {"alpha": 2}})", "controller.sliding_mode_position.alpha"},
  };
  for (const auto& [body, field] : cases) ExpectErrorNames(R"({"duration_s": 0.1, )" + body + "}", field);
}

}  // namespace
}  // namespace vb::experiment

namespace vb::experiment {
namespace {

TEST(Spec, EffectsAndParamOffsetsReachThePlant) {
  auto spec = ParseSpecJson(std::string(R"({"duration_s": 0.1, "bench": {"model": {"preset": "taghizadeh2009",
      "effects": [{"name": "supply_resistance", "params": {"R_s": 0.8}}, {"name": "param:R", "params": {"factor": 1.12}},
                  {"name": "sensor_lag", "params": {"tau_s": 0.0001}}]}}, )") + kPwm + "}");
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  auto e = BuildExperiment(*spec);
  ASSERT_TRUE(e.ok()) << e.status().message();
  EXPECT_DOUBLE_EQ(e->plant.effects.supply_R_ohm, 0.8);
  EXPECT_DOUBLE_EQ(e->plant.R_ohm, 13.0 * 1.12);
  EXPECT_DOUBLE_EQ(e->plant.effects.sensor_tau_s, 1e-4);
  ExpectErrorNames(R"({"duration_s": 0.1, "bench": {"model": {"effects": [{"name": "gremlins"}]}}, )" + std::string(kPwm) + "}",
                   "bench.model.effects[0].name");
  ExpectErrorNames(R"({"duration_s": 0.1, "bench": {"model": {"effects": [{"name": "eddy_currents", "params": {"R_p": -4}}]}}, )" +
                       std::string(kPwm) + "}",
                   "bench.model.effects[0].params[R_p]");
  ExpectErrorNames(R"({"duration_s": 0.1, "bench": {"model": {"effects": [{"name": "param:Q", "params": {"value": 1}}]}}, )" +
                       std::string(kPwm) + "}",
                   "bench.model.effects[0].name");
}

}  // namespace
}  // namespace vb::experiment
