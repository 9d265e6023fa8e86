// benchctl as a user runs it: exit codes, JSON, CSV, errors naming the field.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "../common/run_command.h"

#include <array>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <memory>
#include <string>

namespace {

using Result = vb::testing::CommandResult;

Result RunBenchctl(const std::string& args) {
  // Local runs are recorded in a store of the test's own.
  return vb::testing::RunCommand("VALVEBENCH_DB=" + ::testing::TempDir() + "/benchctl-cli-" +
                                 std::to_string(::getpid()) + ".db " + std::string(VB_BENCHCTL) + " " + args);
}

std::string Example(const std::string& rel) { return std::string(VB_SOURCE_DIR) + "/examples/" + rel; }

TEST(BenchctlCli, RunLocalWritesCsvAndJson) {
  const std::string csv = ::testing::TempDir() + "/e3.csv";
  Result r = RunBenchctl("run --local " + Example("standard/e3.json") + " --json --trace-csv " + csv);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("\"status\": \"done\""), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"samples\": 5001"), std::string::npos) << r.out;
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header.rfind("t_s,gate,v_coil_V,i_A,x_m", 0), 0u) << header;
  size_t lines = 0;
  for (std::string line; std::getline(in, line);) ++lines;
  EXPECT_EQ(lines, 5001u);
}

TEST(BenchctlCli, BadSpecExitsTwoAndNamesTheField) {
  const std::string path = ::testing::TempDir() + "/bad.json";
  std::ofstream(path) << R"({"duration_s": 1, "conditions": {"supply_V": -1},
    "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.4}]}}})";
  Result r = RunBenchctl("run --local " + path);
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("conditions.supply_V"), std::string::npos) << r.out;
  Result missing = RunBenchctl("run --local /nonexistent/spec.json");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  Result no_server = RunBenchctl("run " + Example("standard/e3.json"));
  EXPECT_EQ(no_server.exit_code, 2) << no_server.out;
  EXPECT_NE(no_server.out.find("--local"), std::string::npos);
}

TEST(BenchctlCli, CompareAndCsvOutputs) {
  Result run = RunBenchctl("run --local " + Example("dither.json") + " --csv");
  ASSERT_EQ(run.exit_code, 0) << run.out;
  EXPECT_EQ(run.out.rfind("name,controller,\"controller.dither_pwm.average_current_A\",status", 0), 0u)
      << "the sweep value is a column: " << run.out;
  size_t rows = 0;
  for (size_t p = run.out.find('\n'); p != std::string::npos; p = run.out.find('\n', p + 1)) ++rows;
  EXPECT_EQ(rows, 5u) << "header + 4 sweep points";

  const std::string results = ::testing::TempDir() + "/runs.json";
  Result json = RunBenchctl("run --local " + Example("dither.json") + " --json > " + results);
  ASSERT_EQ(json.exit_code, 0) << json.out;
  {
    std::ifstream in(results);
    std::stringstream ss;
    ss << in.rdbuf();
    // Each run's identity travels as fields: the comparison groups on them, never on the name.
    EXPECT_NE(ss.str().find("\"key\": {"), std::string::npos) << ss.str().substr(0, 400);
    EXPECT_NE(ss.str().find("\"field\": \""), std::string::npos) << ss.str().substr(0, 400);
  }
  Result cmp = RunBenchctl("compare " + results + " --csv");
  ASSERT_EQ(cmp.exit_code, 0) << cmp.out;
  EXPECT_EQ(cmp.out.rfind("rank,name,controller", 0), 0u) << cmp.out;

  Result bad = RunBenchctl("compare " + Example("standard/e1.json"));
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("metrics"), std::string::npos) << bad.out;
}

TEST(BenchctlCli, LocalRunsAreRecordedAndComparableByBatch) {
  Result run = RunBenchctl("run --local " + Example("compare-current-controllers.json") + " --json");
  ASSERT_EQ(run.exit_code, 0) << run.out;
  const size_t at = run.out.find("\"batch_id\": ");
  ASSERT_NE(at, std::string::npos) << run.out;
  const std::string batch = run.out.substr(at + 12, run.out.find_first_of(",\n", at + 12) - at - 12);
  Result cmp = RunBenchctl("compare --local --batch " + batch + " --csv");
  ASSERT_EQ(cmp.exit_code, 0) << cmp.out;
  EXPECT_NE(cmp.out.find("fuzzy_current"), std::string::npos) << cmp.out;
  EXPECT_NE(cmp.out.find("hysteresis_current"), std::string::npos) << cmp.out;
  Result cmp_json = RunBenchctl("compare --local --batch " + batch + " --json");
  ASSERT_EQ(cmp_json.exit_code, 0) << cmp_json.out;
  EXPECT_NE(cmp_json.out.find("\"columns\": ["), std::string::npos) << cmp_json.out;
  EXPECT_NE(cmp_json.out.find("\"failed\": 0"), std::string::npos) << cmp_json.out;
  Result missing = RunBenchctl("compare --local --batch 999999");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  Result unstored = RunBenchctl("run --local " + Example("standard/e3.json") + " --json --no-store");
  ASSERT_EQ(unstored.exit_code, 0) << unstored.out;
  EXPECT_EQ(unstored.out.find("run_id"), std::string::npos) << "--no-store records nothing";
}

TEST(BenchctlCli, DiagnoseReportsJsonAndRefusesBadData) {
  const std::string practice = std::string(VB_SHARED_DIR) + "/gapbench/practice/";
  Result none = RunBenchctl("diagnose " + practice + "p12 --json");
  if (none.out.find("does not exist") != std::string::npos) GTEST_SKIP() << "no practice data";
  ASSERT_EQ(none.exit_code, 0) << none.out;
  EXPECT_NE(none.out.find("\"verdict\": \"none\""), std::string::npos) << none.out;
  // A gap, its cause, and the improved model: with it, the same data shows no gap any more.
  const std::string file = ::testing::TempDir() + "/p07.json", improved = ::testing::TempDir() + "/p07-model.json";
  Result gap = RunBenchctl("diagnose " + practice + "p07 --json " + file + " --emit-model " + improved);
  ASSERT_EQ(gap.exit_code, 0) << gap.out;
  EXPECT_NE(gap.out.find("SIGNIFICANT"), std::string::npos) << gap.out;
  EXPECT_NE(gap.out.find("verdict: supply_resistance"), std::string::npos) << gap.out;
  std::ifstream in(file);
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_NE(ss.str().find("\"significant\": true"), std::string::npos);
  EXPECT_NE(ss.str().find("\"verdict\": \"supply_resistance\""), std::string::npos);
  Result after = RunBenchctl("diagnose " + practice + "p07 --model " + improved + " --json");
  ASSERT_EQ(after.exit_code, 0) << after.out;
  EXPECT_NE(after.out.find("\"verdict\": \"none\""), std::string::npos) << after.out;
  Result bad = RunBenchctl("diagnose /nonexistent/dataset");
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  Result bad_model = RunBenchctl("diagnose " + practice + "p12 --model nosuchmodel");
  EXPECT_EQ(bad_model.exit_code, 2) << bad_model.out;
  EXPECT_NE(bad_model.out.find("--model"), std::string::npos) << bad_model.out;
}

// identify: a bounded fit of named parameters; p05's coil resistance is 12 % high (14.56 ohm).
TEST(BenchctlCli, IdentifyFitsNamedParametersAndWritesAModel) {
  const std::string practice = std::string(VB_SHARED_DIR) + "/gapbench/practice/";
  const std::string out = ::testing::TempDir() + "/p05-identified.json";
  Result r = RunBenchctl("identify " + practice + "p05 --params R --out " + out + " --json");
  if (r.out.find("does not exist") != std::string::npos) GTEST_SKIP() << "no practice data";
  ASSERT_EQ(r.exit_code, 0) << r.out;
  auto j = nlohmann::json::parse(r.out.substr(r.out.find('{')));
  EXPECT_NEAR(j["params"]["R"]["value"].get<double>(), 14.56, 0.05);
  EXPECT_GT(j["params"]["R"]["sigma"].get<double>(), 0.0);
  EXPECT_LT(j["holdout_rmse_after_A"].get<double>(), 3e-3);
  Result check = RunBenchctl("diagnose " + practice + "p05 --model " + out + " --json");
  EXPECT_NE(check.out.find("\"verdict\": \"none\""), std::string::npos) << check.out;
  Result bad = RunBenchctl("identify " + practice + "p05 --params R,flux_capacitor");
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("flux_capacitor"), std::string::npos) << bad.out;
}

}  // namespace
