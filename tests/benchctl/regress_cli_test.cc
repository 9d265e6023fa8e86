// benchctl baseline / regress as CI runs them, on the embedded emulator: exit codes, JUnit XML naming the metric
// and both numbers, versioned baselines, and repeat noise that never fails an unchanged suite.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "../common/run_command.h"

namespace {

using Result = vb::testing::CommandResult;
namespace fs = std::filesystem;

class RegressCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/regress-cli-" + std::to_string(::getpid()) + "-" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    db_ = dir_ + "/local.db";
    // The example CI suite, copied so that tests can change its spec.
    for (const char* f : {"ci.json", "ci-current-hold.json"})
      fs::copy_file(std::string(VB_SOURCE_DIR) + "/examples/suites/" + f, dir_ + "/" + f);
  }
  void TearDown() override { fs::remove_all(dir_); }

  Result Benchctl(const std::string& args) {
    return vb::testing::RunCommand(std::string(VB_BENCHCTL) + " " + args + " --db " + db_);
  }
  static std::string Read(const std::string& path) {
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  // Changes the PI variant of the CI suite's spec (a worse gain, as a code change would).
  void SetPiGains(const std::string& json) {
    std::string spec = Read(dir_ + "/ci-current-hold.json");
    const std::string from = R"("name": "pi",)";
    const size_t at = spec.find(from);
    ASSERT_NE(at, std::string::npos);
    const size_t law = spec.find("\"pi_current\": {}", at);
    ASSERT_NE(law, std::string::npos);
    spec.replace(law, 16, "\"pi_current\": " + json);
    std::ofstream(dir_ + "/ci-current-hold.json") << spec;
  }

  std::string dir_, db_;
};

TEST_F(RegressCli, UnchangedPassesWorsenedGainFailsWithNamesAndNumbers) {
  Result set = Benchctl("baseline set main --suite " + dir_ + "/ci.json --local");
  ASSERT_EQ(set.exit_code, 0) << set.out;
  EXPECT_NE(set.out.find("baseline main version 1 stored"), std::string::npos) << set.out;

  const std::string ok_xml = dir_ + "/ok.xml";
  Result same = Benchctl("regress " + dir_ + "/ci.json --baseline main --local --junit " + ok_xml);
  EXPECT_EQ(same.exit_code, 0) << same.out;
  EXPECT_NE(same.out.find("PASSED"), std::string::npos) << same.out;
  const std::string ok = Read(ok_xml);
  EXPECT_NE(ok.find("failures=\"0\""), std::string::npos) << ok;
  EXPECT_NE(ok.find("<testcase classname=\"ci.hold/pi\" name=\"rmse\">"), std::string::npos) << ok;
  // Kept by the local service beside its batch, and read back through it (GetRegression).
  EXPECT_NE(same.out.find("regression 1 stored in local store " + db_), std::string::npos) << same.out;
  Result page = Benchctl("report --regress 1 --html " + dir_ + "/r1.html");
  EXPECT_EQ(page.exit_code, 0) << page.out;
  EXPECT_NE(page.out.find("Regression 1: suite ci"), std::string::npos) << page.out;
  Result none = Benchctl("report --regress 99 --html " + dir_ + "/r99.html");
  EXPECT_EQ(none.exit_code, 2) << none.out;
  EXPECT_NE(none.out.find("regression 99 not found"), std::string::npos) << none.out;

  // A tenth of the default proportional gain: RMSE 0.83 -> 4.2 mA. (A tenth of the integral gain worsened the
  // RMSE sampled at one phase of the ripple, 0.31 -> 1.1 mA, but from the trajectory it improves it, 0.83 ->
  // 0.56 mA: issue 37, docs/regress.md.)
  SetPiGains(R"({"kp_V_per_A": 37.7})");
  const std::string bad_xml = dir_ + "/bad.xml";
  Result worse = Benchctl("regress " + dir_ + "/ci.json --baseline main --local --junit " + bad_xml);
  EXPECT_EQ(worse.exit_code, 1) << worse.out;
  EXPECT_NE(worse.out.find("REGRESSED  hold/pi  rmse regressed: baseline 0.000"), std::string::npos) << worse.out;
  const std::string xml = Read(bad_xml);
  const size_t tc = xml.find("<testcase classname=\"ci.hold/pi\" name=\"rmse\">");
  ASSERT_NE(tc, std::string::npos) << xml;
  const size_t failure = xml.find("<failure type=\"regression\" message=\"rmse regressed: baseline ", tc);
  ASSERT_NE(failure, std::string::npos) << xml;
  EXPECT_LT(failure, xml.find("</testcase>", tc));
  EXPECT_NE(xml.find("-&gt; now ", failure), std::string::npos);
  EXPECT_NE(xml.find("failures=\"1\""), std::string::npos) << xml;
  // Only that metric regressed: the hysteresis law and the map are untouched.
  EXPECT_EQ(xml.find("<failure", failure + 10), std::string::npos) << xml;

  // --json carries the same verdict and numbers.
  Result js = Benchctl("regress " + dir_ + "/ci.json --baseline main --local --json");
  EXPECT_EQ(js.exit_code, 1);
  EXPECT_NE(js.out.find("\"verdict\": \"regressed\""), std::string::npos) << js.out;
}

TEST_F(RegressCli, RepeatNoiseAloneNeverFails) {
  // Baseline at seed 1; reruns at other seeds draw other supply and coil-resistance jitter for every repeat.
  ASSERT_EQ(Benchctl("baseline set main --suite " + dir_ + "/ci.json --local --seed 1").exit_code, 0);
  for (int seed = 2; seed <= 6; ++seed) {
    Result r = Benchctl("regress " + dir_ + "/ci.json --baseline main --local --seed " + std::to_string(seed));
    EXPECT_EQ(r.exit_code, 0) << "seed " << seed << "\n" << r.out;
    EXPECT_EQ(r.out.find("REGRESSED  "), std::string::npos) << r.out;
  }
}

TEST_F(RegressCli, BaselinesAreVersionedNeverOverwritten) {
  ASSERT_EQ(Benchctl("baseline set main --suite " + dir_ + "/ci.json --local --note first").exit_code, 0);
  Result list1 = Benchctl("baseline list --json");
  ASSERT_EQ(list1.exit_code, 0);
  // The runs of the suite are a batch in the local store: a baseline can be taken from it too.
  Result again = Benchctl("baseline set main --batch 1 --local");
  ASSERT_EQ(again.exit_code, 0) << again.out;
  EXPECT_NE(again.out.find("version 2 stored"), std::string::npos) << again.out;
  EXPECT_NE(again.out.find("versions 1-1 are kept"), std::string::npos) << again.out;
  Result list = Benchctl("baseline list");
  EXPECT_NE(list.out.find("v1"), std::string::npos) << list.out;
  EXPECT_NE(list.out.find("v2"), std::string::npos) << list.out;
  Result v1 = Benchctl("baseline show main --version 1 --json");
  ASSERT_EQ(v1.exit_code, 0) << v1.out;
  EXPECT_NE(v1.out.find("\"note\": \"first\""), std::string::npos) << v1.out;
  EXPECT_NE(v1.out.find("\"hold/pi\""), std::string::npos);
  // The JSON of show is a baseline file regress accepts (how CI keeps its baseline in the repository).
  std::ofstream(dir_ + "/baseline.json") << v1.out;
  Result from_file = Benchctl("regress " + dir_ + "/ci.json --baseline " + dir_ + "/baseline.json --local");
  EXPECT_EQ(from_file.exit_code, 0) << from_file.out;
  Result v9 = Benchctl("baseline show main --version 9");
  EXPECT_EQ(v9.exit_code, 2);
  EXPECT_NE(v9.out.find("no version 9"), std::string::npos) << v9.out;
}

TEST_F(RegressCli, BadInputExitsTwoNamingTheProblemAndKeepsBaselines) {
  ASSERT_EQ(Benchctl("baseline set main --suite " + dir_ + "/ci.json --local").exit_code, 0);
  Result missing = Benchctl("regress " + dir_ + "/ci.json --baseline nope --local");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  EXPECT_NE(missing.out.find("baseline 'nope' not found"), std::string::npos) << missing.out;
  std::ofstream(dir_ + "/bad.json") << R"({"name": "x", "experiments": [{"name": "a", "spec_file": "ci-current-hold.json",
      "tolerances": [{"metric": "rsme", "relative": 0.1}]}]})";
  Result bad = Benchctl("regress " + dir_ + "/bad.json --baseline main --local");
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("experiments[0].tolerances[0].metric: unknown metric 'rsme'"), std::string::npos) << bad.out;
  std::ofstream(dir_ + "/bl.json") << R"({"name": "x", "cases": {"a": {"rmse": {"mean": 1, "spread": -2, "n": 3}}}})";
  Result bad_file = Benchctl("regress " + dir_ + "/ci.json --baseline " + dir_ + "/bl.json --local");
  EXPECT_EQ(bad_file.exit_code, 2) << bad_file.out;
  EXPECT_NE(bad_file.out.find("cases.a.rmse.spread"), std::string::npos) << bad_file.out;
  Result both = Benchctl("baseline set main --local");
  EXPECT_EQ(both.exit_code, 2);
  EXPECT_NE(both.out.find("exactly one of --batch B and --suite SUITE"), std::string::npos) << both.out;
  Result no_batch = Benchctl("baseline set main --batch 999 --local");
  EXPECT_EQ(no_batch.exit_code, 2) << no_batch.out;
  // Nothing stored was lost or replaced by the refused calls.
  Result list = Benchctl("baseline list --json");
  EXPECT_NE(list.out.find("\"version\": 1"), std::string::npos) << list.out;
  EXPECT_EQ(list.out.find("\"version\": 2"), std::string::npos) << list.out;
}

}  // namespace
