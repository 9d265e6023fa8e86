// valve-runs/2: every run kind loads with its covariates, the sense chain and the driver; every rule has an
// error that names the field; a waveform that does not start from rest is refused unless it says so.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "gap/dataset.h"
#include "model/params.h"

namespace vb::gap {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class DatasetV2Test : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    root_ = fs::path(::testing::TempDir()) / ("vb_v2_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    dir_ = root_ / "ds";
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(root_); }
  void Write(const std::string& rel, const std::string& content) { std::ofstream(dir_ / rel, std::ios::binary) << content; }

  static json Manifest() {
    return json{
        {"format", "valve-runs/2"},
        {"model", "ts98_coil"},
        {"device", "coil-1"},
        {"sensor", {{"shunt_ohm", 0.2}, {"shunt_in_switch_path", true}, {"amplifier_gain", 20.0}, {"adc_lsb_V", 0.001},
                    {"noise_A", 1e-4}, {"offset_A", 0.002}, {"averaged", 16}}},
        {"driver", {{"kind", "low_side_flyback"}, {"diode_drop_V", 0.4}}},
        {"runs",
         {{{"id", "p1"}, {"kind", "periodic"}, {"supply_V", 5.0}, {"pwm_Hz", 100}, {"on_time_s", 0.002},
           {"coil_C", 31.5}, {"stroke_m", 0.001}, {"split", "fit"},
           {"readings", {{{"t_after_edge_s", 1e-4}, {"i_A", 0.02}, {"sd_A", 1e-4}, {"repeats", 10}},
                         {{"t_after_edge_s", 7e-4}, {"i_A", 0.05}}}}},
          {{"id", "s1"}, {"kind", "samples"}, {"file", "s1.csv"}, {"supply_V", 5.0}, {"ambient_C", 22.0},
           {"gate_edges_s", {0.001, 0.004}}},
          {{"id", "w1"}, {"file", "w1.csv"}, {"supply_V", 24.0}, {"t_start_s", 3.0}}}}};
  }
  void WriteAll(const json& m) {
    Write("manifest.json", m.dump(1));
    Write("s1.csv", "t_s,i_A,i_sd_A\n0.0005,0,0.0001\n0.0021,0.03,0.0001\n0.0093,0.004,0.0001\n");
    // Readings carry the declared 2 mA offset: at rest they read 2 mA.
    Write("w1.csv", "t_s,gate,i_A\n0,0,0.002\n2e-05,0,0.0021\n4e-05,0,0.002\n6e-05,1,0.003\n8e-05,1,0.004\n");
  }
  StatusOr<Dataset> Load() { return LoadDataset(dir_.string(), model::PresetNames()); }
  void ExpectError(const json& m, const std::string& message) {
    WriteAll(m);
    auto ds = Load();
    ASSERT_FALSE(ds.ok()) << "expected: " << message;
    EXPECT_EQ(ds.status().message(), message);
  }

  fs::path root_, dir_;
};

TEST_F(DatasetV2Test, EveryRunKindLoadsWithItsCovariatesSenseChainAndDriver) {
  WriteAll(Manifest());
  auto ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  EXPECT_EQ(ds->format, "valve-runs/2");
  EXPECT_EQ(ds->device, "coil-1");
  EXPECT_TRUE(ds->warnings.empty()) << ds->warnings.front();
  EXPECT_DOUBLE_EQ(ds->sensor.adc_lsb_A, 0.001 / (0.2 * 20.0));
  EXPECT_TRUE(ds->sensor.shunt_in_switch_path);
  EXPECT_EQ(ds->sensor.averaged, 16);
  EXPECT_DOUBLE_EQ(ds->driver.diode_drop_V, 0.4);
  ASSERT_EQ(ds->runs.size(), 3u);
  const RunData& p = ds->runs[0];
  EXPECT_EQ(p.kind, RunKind::kPeriodic);
  EXPECT_EQ(p.t_s, (std::vector<double>{1e-4, 7e-4}));
  EXPECT_EQ(p.i_A, (std::vector<double>{0.02, 0.05}));
  EXPECT_EQ(p.repeats, (std::vector<int>{10, 1}));
  EXPECT_DOUBLE_EQ(p.temperature_C(), 31.5);
  EXPECT_DOUBLE_EQ(p.stroke_m, 0.001);
  EXPECT_TRUE(std::isnan(p.t_start_s));
  const RunData& s = ds->runs[1];
  EXPECT_EQ(s.kind, RunKind::kSamples);
  EXPECT_EQ(s.gate_edges_s, (std::vector<double>{0.001, 0.004}));
  EXPECT_EQ(s.i_sd_A.size(), 3u);
  EXPECT_DOUBLE_EQ(s.temperature_C(), 22.0);  // ambient when the coil's is not recorded
  EXPECT_EQ(ds->runs[2].kind, RunKind::kWaveform);
  // Standard errors: spread over repeats, the ADC step, the declared noise over averaging and repeats.
  const auto se = DeclaredStandardErrors(*ds, p);
  const double lsb = ds->sensor.adc_lsb_A;
  EXPECT_NEAR(se[0], std::sqrt(1e-8 / 10 + lsb * lsb / 12 / 10 + 1e-8 / 160), 1e-12);
  EXPECT_NEAR(se[1], std::sqrt(lsb * lsb / 12 + 1e-8 / 16), 1e-12);
}

TEST_F(DatasetV2Test, ValveRuns1KeepsLoadingAndModelFilesAreFoundBesideTheManifest) {
  json m = Manifest();
  m["model"] = "coil.json";
  Write("coil.json", R"({"preset": "ts98_coil", "params": {"R": 30}})");
  WriteAll(m);
  auto ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  EXPECT_EQ(ds->model_file, (dir_ / "coil.json").string());
  m["model"] = "missing.json";
  ExpectError(m, "ds/manifest.json: model: 'missing.json' does not exist");
}

TEST_F(DatasetV2Test, FieldErrorsNameTheField) {
  auto with = [](auto edit) {
    json m = Manifest();
    edit(m);
    return m;
  };
  ExpectError(with([](json& m) { m["runs"][0]["kind"] = "burst"; }),
              "ds/manifest.json: runs[0].kind: 'burst' is not waveform, samples or periodic");
  ExpectError(with([](json& m) { m["runs"][0]["file"] = "x.csv"; }),
              "ds/manifest.json: runs[0].file: not allowed for a periodic run (its readings are in the manifest)");
  ExpectError(with([](json& m) { m["runs"][0]["on_time_s"] = 0.02; }),
              "ds/manifest.json: runs[0].on_time_s: 0.02 s is outside (0, 0.01] s, the PWM period");
  ExpectError(with([](json& m) { m["runs"][0]["readings"][1]["t_after_edge_s"] = 0.01; }),
              "ds/manifest.json: runs[0].readings[1].t_after_edge_s: 0.01 s is outside [0, 0.01) s, the PWM period");
  ExpectError(with([](json& m) { m["runs"][0]["readings"][0]["repeats"] = 2.5; }),
              "ds/manifest.json: runs[0].readings[0].repeats: 2.5 is not a whole number");
  ExpectError(with([](json& m) { m["runs"][0]["readings"] = json::array(); }),
              "ds/manifest.json: runs[0].readings: must not be empty");
  ExpectError(with([](json& m) { m["runs"][0]["coil_C"] = 900; }),
              "ds/manifest.json: runs[0].coil_C: 900 C is outside [-100, 400] C");
  ExpectError(with([](json& m) { m["runs"][0]["stroke_m"] = -0.001; }),
              "ds/manifest.json: runs[0].stroke_m: -0.001 m is outside [0, 1] m");
  ExpectError(with([](json& m) { m["runs"][1].erase("gate_edges_s"); }),
              "ds/manifest.json: runs[1].gate_edges_s: missing (a samples run needs its gate command)");
  ExpectError(with([](json& m) { m["runs"][1]["gate_edges_s"] = {0.004, 0.001}; }),
              "ds/manifest.json: runs[1].gate_edges_s[1]: 0.001 s does not come after the previous edge");
  ExpectError(with([](json& m) { m["runs"][2]["pwm_Hz"] = 100; }),
              "ds/manifest.json: runs[2].pwm_Hz: not allowed for a waveform run (only periodic runs take it)");
  ExpectError(with([](json& m) { m["runs"][2]["supply_V"] = 1e6; }),
              "ds/manifest.json: runs[2].supply_V: 1000000 V is outside (0, 10000] V");
  ExpectError(with([](json& m) { m["sensor"].erase("shunt_ohm"); }),
              "ds/manifest.json: sensor.shunt_in_switch_path: needs sensor.shunt_ohm");
  ExpectError(with([](json& m) { m["driver"]["kind"] = "triac"; }),
              "ds/manifest.json: driver.kind: unknown driver 'triac' (known: low_side_flyback, h_bridge, internal_electronics)");
}

TEST_F(DatasetV2Test, AWaveformThatDoesNotStartFromRestIsRefusedUnlessItSaysSo) {
  json m = Manifest();
  WriteAll(m);
  Write("w1.csv", "t_s,gate,i_A\n0,0,0.3\n2e-05,0,0.29\n4e-05,0,0.28\n6e-05,1,0.28\n8e-05,1,0.3\n");
  auto ds = Load();
  ASSERT_FALSE(ds.ok());
  EXPECT_NE(ds.status().message().find("runs[2].from_rest: run 'w1' starts at i_A = 0.288 A, not at rest"),
            std::string::npos)
      << ds.status().message();
  m["runs"][2]["from_rest"] = false;
  Write("manifest.json", m.dump());
  ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  EXPECT_FALSE(ds->runs[2].from_rest);
}

TEST_F(DatasetV2Test, SamplesCsvErrorsNameLineAndColumn) {
  WriteAll(Manifest());
  Write("s1.csv", "t_s,i_A\n0.002,0\n0.001,0.1\n");
  auto ds = Load();
  ASSERT_FALSE(ds.ok());
  EXPECT_EQ(ds.status().message(), "ds/s1.csv:3: column t_s: time does not increase (0.001 s after 0.002 s)");
  Write("s1.csv", "t_s,gate,i_A\n0.001,1,0\n");
  ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  EXPECT_EQ(ds->warnings.size(), 1u);  // gate is not a samples column: the edges are in the manifest
}

}  // namespace
}  // namespace vb::gap
