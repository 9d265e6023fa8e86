// benchctl prune (benchctl/prune_command.cc, docs/store.md "Retention"): on the local store and, through the
// admin-only PruneRuns RPC, on a real server. The store's rules have their own tests (tests/db/prune_test.cc);
// these check the command and the RPC: ages, exit codes, roles, dry run, JSON, what is deleted and kept.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <thread>

#include <nlohmann/json.hpp>

#include "benchctl/prune_command.h"
#include "client/client.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "experiment/spec.h"
#include "server_process.h"

namespace vb {
namespace {

namespace v1 = valvebench::v1;
using Json = nlohmann::json;
using testing::ServerProcess;

struct Result {
  int exit_code = -1;
  std::string out;
};

Result Benchctl(const std::string& args) {
  Result r;
  const std::string cmd = std::string(VB_BENCHCTL) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  if (p == nullptr) return r;
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p) != nullptr) r.out += buf.data();
  const int st = pclose(p);
  r.exit_code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

std::string TempDir(const std::string& name) {
  const std::string d = ::testing::TempDir() + "/vb-prune-" + name + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

TEST(PruneAge, ParsesUnitsAndRefusesNonsenseNamingTheFlag) {
  EXPECT_EQ(*benchctl::ParseAge("30d"), 30 * 86400.0);
  EXPECT_EQ(*benchctl::ParseAge("12h"), 12 * 3600.0);
  EXPECT_EQ(*benchctl::ParseAge("90m"), 90 * 60.0);
  EXPECT_EQ(*benchctl::ParseAge("3600s"), 3600.0);
  EXPECT_EQ(*benchctl::ParseAge("2w"), 14 * 86400.0);
  EXPECT_EQ(*benchctl::ParseAge("1.5d"), 1.5 * 86400.0);
  for (const char* bad : {"", "d", "30", "30x", "abcd", "-1d", "0d", "nand", "1e9w", "3 d"}) {
    auto a = benchctl::ParseAge(bad);
    ASSERT_FALSE(a.ok()) << bad;
    EXPECT_EQ(a.status().code(), StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(a.status().message().find("--older-than"), std::string::npos) << a.status().message();
  }
}

TEST(PruneCommand, LocalStoreDryRunThenDeleteKeepingTheNewestAndExitCodes) {
  const std::string dir = TempDir("local");
  const std::string db = dir + "/local.db";
  for (int k = 0; k < 3; ++k) {
    Result r = Benchctl("run --local " + std::string(VB_SOURCE_DIR) + "/examples/standard/e3.json --db " + db);
    ASSERT_EQ(r.exit_code, 0) << r.out;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));

  Result dry = Benchctl("prune --older-than 1s --keep-last 1 --dry-run --json --db " + db);
  ASSERT_EQ(dry.exit_code, 0) << dry.out;
  const Json d = Json::parse(dry.out);
  EXPECT_TRUE(d["dry_run"].get<bool>());
  ASSERT_EQ(d["deleted"].size(), 2u) << dry.out;
  ASSERT_EQ(d["kept"].size(), 1u);
  EXPECT_EQ(d["kept"][0]["run_id"], 3);
  EXPECT_NE(d["kept"][0]["why"].get<std::string>().find("--keep-last"), std::string::npos);
  {
    auto store = db::OpenSqliteStore(db);
    ASSERT_TRUE(store.ok());
    for (std::int64_t id : {1, 2, 3}) EXPECT_TRUE((*store)->GetRun(id).ok()) << "a dry run deleted run " << id;
  }

  Result text = Benchctl("prune --older-than 1s --keep-last 1 --db " + db);
  ASSERT_EQ(text.exit_code, 0) << text.out;
  EXPECT_NE(text.out.find("deleted 2 run(s)"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("one of the newest 1 finished runs"), std::string::npos) << text.out;
  auto store = db::OpenSqliteStore(db);
  ASSERT_TRUE(store.ok());
  EXPECT_EQ((*store)->GetRun(1).status().code(), StatusCode::kNotFound);
  EXPECT_EQ((*store)->GetRun(2).status().code(), StatusCode::kNotFound);
  auto kept = (*store)->ReadTrace(3);
  ASSERT_TRUE(kept.ok());
  EXPECT_FALSE(kept->empty());

  // Nothing is as old as a day: nothing goes.
  Result none = Benchctl("prune --older-than 1d --json --db " + db);
  ASSERT_EQ(none.exit_code, 0) << none.out;
  EXPECT_EQ(Json::parse(none.out)["deleted"].size(), 0u);
  EXPECT_EQ(Json::parse(none.out)["newer_kept"], 1);

  Result bad = Benchctl("prune --older-than soon --db " + db);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.out.find("--older-than"), std::string::npos) << bad.out;
  Result missing = Benchctl("prune --older-than 1d --db " + dir + "/nothing-here.db");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  EXPECT_NE(missing.out.find("no local store"), std::string::npos) << missing.out;
  EXPECT_FALSE(std::filesystem::exists(dir + "/nothing-here.db"));
  Result no_age = Benchctl("prune --db " + db);
  EXPECT_EQ(no_age.exit_code, 2) << no_age.out;
}

TEST(PruneCommand, ServerPrunesThroughTheAdminRpcAndKeepsTheNightsBaselineBatch) {
  const std::string dir = TempDir("server");
  // The nights' baseline file was taken from this server's batch 2: its run must survive any prune.
  const std::string suites = std::string(VB_SOURCE_DIR) + "/examples/suites/";
  {
    std::ifstream in(suites + "ci-baseline.json");
    Json b = Json::parse(in);
    b["source"] = "suite ci (server lab:50051 batch 2, seed 1)";
    std::ofstream(dir + "/baseline.json") << b.dump(2);
  }
  ServerProcess server(dir, R"("nights": {"cron": "0 2 * * *", "suite_file": ")" + suites +
                                R"(ci.json", "baseline_file": "baseline.json", "timezone": "UTC"})");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  client::ClientOptions o;
  o.address = addr;
  o.token = testing::kOperatorToken;
  client::Client c(o);
  auto spec = experiment::ParseSpecJson(R"({"name": "p", "duration_s": 0.02,
      "conditions": {"supply_V": 24, "supply_pressure_Pa": 400000},
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}},
      "recording": {"rate_Hz": 10000}})");
  ASSERT_TRUE(spec.ok());
  std::vector<std::int64_t> ids;
  for (int k = 0; k < 3; ++k) {
    auto s = c.Submit(*spec);
    ASSERT_TRUE(s.ok()) << s.status().message();
    ids.push_back(s->run_ids(0));
  }
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  for (std::int64_t id : ids) {
    while (true) {
      auto r = c.GetRun(id);
      ASSERT_TRUE(r.ok());
      if (r->status() == v1::DONE) break;
      ASSERT_LT(std::chrono::steady_clock::now(), until) << "run " << id << " did not finish";
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  const std::string remote = "--server " + addr + " --token ";

  // Only an admin may prune; the operator is refused (exit 2) and nothing is deleted.
  Result denied = Benchctl("prune --older-than 1s " + remote + testing::kOperatorToken);
  EXPECT_EQ(denied.exit_code, 2) << denied.out;
  EXPECT_NE(denied.out.find("admin"), std::string::npos) << denied.out;
  EXPECT_TRUE(c.GetRun(ids[0]).ok());

  Result dry = Benchctl("prune --older-than 1s --dry-run --json " + remote + testing::kAdminToken);
  ASSERT_EQ(dry.exit_code, 0) << dry.out;
  EXPECT_EQ(Json::parse(dry.out)["deleted"].size(), 2u) << dry.out;
  EXPECT_TRUE(c.GetRun(ids[0]).ok());

  Result bad = Benchctl("prune --older-than 1s --keep-last -3 " + remote + testing::kAdminToken);
  EXPECT_EQ(bad.exit_code, 2) << bad.out;

  Result real = Benchctl("prune --older-than 1s --json " + remote + testing::kAdminToken);
  ASSERT_EQ(real.exit_code, 0) << real.out;
  const Json j = Json::parse(real.out);
  EXPECT_FALSE(j["dry_run"].get<bool>());
  ASSERT_EQ(j["deleted"].size(), 2u) << real.out;
  EXPECT_GT(j["trace_bytes"].get<std::int64_t>(), 0);
  ASSERT_EQ(j["kept"].size(), 1u) << real.out;
  EXPECT_EQ(j["kept"][0]["run_id"], ids[1]);
  EXPECT_EQ(j["kept"][0]["batch_id"], 2);
  EXPECT_NE(j["kept"][0]["why"].get<std::string>().find("nights' baseline file"), std::string::npos) << real.out;
  EXPECT_EQ(c.GetRun(ids[0]).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(c.GetRun(ids[2]).status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(c.GetRun(ids[1]).ok());
  auto trace = c.GetTrace(ids[1]);
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  EXPECT_GT(trace->samples(), 0u);
}

}  // namespace
}  // namespace vb
