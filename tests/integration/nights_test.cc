// Nights (docs/regress.md "Nights"): the server runs examples/suites/ci.json on its emulated benches, triggered
// at start by the hidden --run-night-now hook, compares it with the committed baseline and lists the night
// through ListNights / `benchctl nights`. And the config's nights block is validated with errors naming fields.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "../common/run_command.h"
#include "client/client.h"
#include "regress/cron.h"
#include "server/config.h"
#include "server_process.h"

namespace vb {
namespace {

const std::string kSuites = std::string(VB_SOURCE_DIR) + "/examples/suites/";

std::string NightsBlock(const std::string& cron) {
  return R"("nights": {"cron": ")" + cron + R"(", "suite_file": ")" + kSuites + R"(ci.json", "baseline_file": ")" +
         kSuites + R"(ci-baseline.json", "timezone": "UTC"})";
}

valvebench::v1::ServerConfig Config(const std::string& cron, const std::string& tz = "UTC") {
  valvebench::v1::ServerConfig c = testing::MinimalConfig();
  c.mutable_nights()->set_cron(cron);
  c.mutable_nights()->set_suite_file(kSuites + "ci.json");
  c.mutable_nights()->set_baseline_file(kSuites + "ci-baseline.json");
  c.mutable_nights()->set_timezone(tz);
  return c;
}

TEST(NightsConfig, ValidatesAndNamesTheField) {
  auto ok = server::SettingsFromConfig(Config("0 2 * * *"), "");
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  EXPECT_TRUE(ok->nights.enabled);
  EXPECT_EQ(ok->nights.suite_path, kSuites + "ci.json");

  auto bad = server::SettingsFromConfig(Config("0 25 * * *"), "");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message().rfind("nights.cron: ", 0), 0u) << bad.status().message();
  EXPECT_NE(bad.status().message().find("hour"), std::string::npos) << bad.status().message();

  auto tz = server::SettingsFromConfig(Config("0 2 * * *", "Europe/Berlin"), "");
  ASSERT_FALSE(tz.ok());
  EXPECT_NE(tz.status().message().find("nights.timezone"), std::string::npos) << tz.status().message();

  auto c = Config("0 2 * * *");
  c.mutable_nights()->set_baseline_file("/nonexistent/baseline.json");
  auto nobase = server::SettingsFromConfig(c, "");
  ASSERT_FALSE(nobase.ok());
  EXPECT_NE(nobase.status().message().find("nights.baseline_file"), std::string::npos) << nobase.status().message();

  // No nights block: nothing scheduled.
  valvebench::v1::ServerConfig none = Config("");
  none.clear_nights();
  auto off = server::SettingsFromConfig(none, "");
  ASSERT_TRUE(off.ok()) << off.status().message();
  EXPECT_FALSE(off->nights.enabled);
}

TEST(NightsConfig, ServerRefusesABadCronAtStart) {
  const std::string dir = ::testing::TempDir() + "/vb-nights-badcron-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(dir, NightsBlock("61 * * * *"));
  EXPECT_EQ(server.Start(), "");
  EXPECT_NE(server.Log().find("nights.cron: "), std::string::npos) << server.Log();
}

TEST(Nights, RunNowStoresAPassingNightListedByBenchctl) {
  const std::string dir = ::testing::TempDir() + "/vb-nights-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(dir, NightsBlock("0 2 * * *"));
  server.AddArg("--run-night-now");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const std::string nights_cmd =
      std::string(VB_BENCHCTL) + " nights --json --server " + addr + " --token " + testing::kViewerToken;

  nlohmann::json list;
  testing::CommandResult r;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < until) {
    r = testing::RunCommand(nights_cmd);
    ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 1) << r.out;
    const size_t at = r.out.find('[');
    list = nlohmann::json::parse(at == std::string::npos ? std::string() : r.out.substr(at), nullptr, false);
    if (list.is_array() && !list.empty()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  ASSERT_TRUE(list.is_array() && list.size() == 1) << r.out << "\n" << server.Log();
  const auto& n = list[0];
  const double now_s = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  EXPECT_EQ(n["verdict"], "passed") << n.dump(2) << "\n" << server.Log();
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(n["date"], regress::DateOf(now_s, true));
  EXPECT_EQ(n["suite"], "ci");
  EXPECT_EQ(n["baseline"], "ci v1");
  EXPECT_EQ(n["regressed"], 0);
  EXPECT_GT(n["unchanged"].get<int>(), 0);
  EXPECT_GT(n["batch_id"].get<std::int64_t>(), 0);
  EXPECT_LE(n["started_unix_s"].get<double>(), n["finished_unix_s"].get<double>());

  // The batch's runs carry the night's tags and were submitted by "nights".
  client::ClientOptions o;
  o.address = addr;
  o.token = testing::kViewerToken;
  client::Client c(o);
  valvebench::v1::ListRunsRequest req;
  req.set_tag("night:" + n["date"].get<std::string>());
  auto runs = c.ListRuns(req);
  ASSERT_TRUE(runs.ok()) << runs.status().message();
  ASSERT_EQ(runs->runs_size(), 9);  // hold: 2 laws x 3 repeats, map: 3 duties
  for (const auto& run : runs->runs()) {
    EXPECT_EQ(run.batch_id(), n["batch_id"].get<std::int64_t>());
    EXPECT_EQ(run.submitter(), "nights");
  }

  // Bad input: exit 2.
  EXPECT_EQ(testing::RunCommand(nights_cmd + " --limit 0").exit_code, 2);
}

// The same suite with the PI law's proportional gain cut tenfold (as in regress_ci_test; since issue 37 the RMSE is
// the trajectory's, and a tenfold smaller integral gain improves this window's): the night regresses and
// `benchctl nights` exits 1 with the first regression in the summary.
TEST(Nights, AWorseControllerMakesARegressedNight) {
  const std::string dir = ::testing::TempDir() + "/vb-nights-worse-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  ASSERT_EQ(testing::WriteWorseCiSuite(kSuites, dir), "");
  testing::ServerProcess server(dir, R"("nights": {"cron": "0 2 * * *", "suite_file": "ci.json", "baseline_file": ")" +
                                         kSuites + R"(ci-baseline.json"})");
  server.AddArg("--run-night-now");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const std::string cmd =
      std::string(VB_BENCHCTL) + " nights --json --server " + addr + " --token " + testing::kViewerToken;
  nlohmann::json list;
  testing::CommandResult r;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < until) {
    r = testing::RunCommand(cmd);
    const size_t at = r.out.find('[');
    list = nlohmann::json::parse(at == std::string::npos ? std::string() : r.out.substr(at), nullptr, false);
    if (list.is_array() && !list.empty()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  ASSERT_TRUE(list.is_array() && list.size() == 1) << r.out << "\n" << server.Log();
  EXPECT_EQ(list[0]["verdict"], "regressed") << list.dump(2);
  EXPECT_GT(list[0]["regressed"].get<int>(), 0);
  EXPECT_NE(list[0]["summary"].get<std::string>().find("first: "), std::string::npos) << list.dump(2);
  EXPECT_EQ(r.exit_code, 1) << r.out;
}

}  // namespace
}  // namespace vb
