// Retention on a schedule (docs/store.md "Retention", docs/server.md "retention"): the config block is
// validated at start with errors naming the field, and the scheduler (server/retention.h), driven by an
// injected clock, prunes at its cron fire with the rules of PruneRuns: an old finished run goes, a queued run
// and the batch the nights' baseline file was taken from stay; an unreadable baseline file deletes nothing.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/testing.h"
#include "regress/cron.h"
#include "server/config.h"
#include "server/retention.h"
#include "server_process.h"

namespace vb {
namespace {

constexpr double kDay_s = 86400.0;

valvebench::v1::ServerConfig Config() {
  valvebench::v1::ServerConfig c = testing::MinimalConfig();
  return c;
}

std::string ErrorOf(const valvebench::v1::ServerConfig& c) {
  auto s = server::SettingsFromConfig(c, "");
  return s.ok() ? std::string("(accepted)") : s.status().message();
}

TEST(RetentionConfig, ValidatesAndNamesTheField) {
  auto none = server::SettingsFromConfig(Config(), "");
  ASSERT_TRUE(none.ok()) << none.status().message();
  EXPECT_FALSE(none->retention.enabled);

  auto c = Config();
  c.mutable_retention()->set_older_than_days(90);
  c.mutable_retention()->set_keep_last(1000);
  auto ok = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  EXPECT_TRUE(ok->retention.enabled);
  EXPECT_EQ(ok->retention.older_than_days, 90.0);
  EXPECT_EQ(ok->retention.keep_last, 1000);
  EXPECT_EQ(ok->retention.cron, "30 3 * * *");  // the default: 03:30 UTC daily

  c.mutable_retention()->set_cron("0 4 * * 0");
  auto weekly = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(weekly.ok()) << weekly.status().message();
  EXPECT_EQ(weekly->retention.cron, "0 4 * * 0");

  auto empty = Config();
  empty.mutable_retention();  // a block without older_than_days
  EXPECT_EQ(ErrorOf(empty).rfind("retention.older_than_days: ", 0), 0u) << ErrorOf(empty);

  auto negative = Config();
  negative.mutable_retention()->set_older_than_days(-1);
  EXPECT_EQ(ErrorOf(negative).rfind("retention.older_than_days: ", 0), 0u) << ErrorOf(negative);
  negative.mutable_retention()->set_older_than_days(std::nan(""));
  EXPECT_EQ(ErrorOf(negative).rfind("retention.older_than_days: ", 0), 0u) << ErrorOf(negative);

  auto keep = Config();
  keep.mutable_retention()->set_older_than_days(90);
  keep.mutable_retention()->set_keep_last(-5);
  EXPECT_EQ(ErrorOf(keep).rfind("retention.keep_last: ", 0), 0u) << ErrorOf(keep);
  EXPECT_NE(ErrorOf(keep).find("-5"), std::string::npos) << ErrorOf(keep);

  auto cron = Config();
  cron.mutable_retention()->set_older_than_days(90);
  cron.mutable_retention()->set_cron("30 25 * * *");
  EXPECT_EQ(ErrorOf(cron).rfind("retention.cron: ", 0), 0u) << ErrorOf(cron);
  EXPECT_NE(ErrorOf(cron).find("hour"), std::string::npos) << ErrorOf(cron);
}

TEST(RetentionConfig, ServerRefusesABadBlockAtStart) {
  const std::string dir = ::testing::TempDir() + "/vb-retention-badcron-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(dir, R"("retention": {"older_than_days": 90, "cron": "61 * * * *"})");
  EXPECT_EQ(server.Start(), "");
  EXPECT_NE(server.Log().find("retention.cron: "), std::string::npos) << server.Log();
}

class RetentionSchedulerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/vb-retention-" + std::to_string(::getpid());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    db_path_ = dir_ + "/store.db";
    auto s = db::OpenSqliteStore(db_path_);
    ASSERT_TRUE(s.ok()) << s.status().message();
    store_ = std::move(s).value();
  }
  void TearDown() override {
    store_.reset();
    std::filesystem::remove_all(dir_);
  }
  // One run in a batch of its own; returns the run id, the batch id in *batch.
  std::int64_t Submit(const std::string& name, std::int64_t* batch) {
    db::RunRecord r;
    r.key = NamedRun(name);
    r.controller = "open_loop_pwm";
    r.bench_kind = "emulated";
    r.spec_json = "{}";
    std::vector<std::int64_t> ids;
    auto b = store_->SubmitBatch("alice", name, "{}", {r}, &ids);
    EXPECT_TRUE(b.ok()) << b.status().message();
    *batch = b.ok() ? *b : 0;
    return ids.empty() ? 0 : ids[0];
  }
  // Runs the next queued run (it must be `id`) to done with a small trace.
  void Finish(std::int64_t id) {
    auto c = store_->ClaimNext(db::BenchClaim("emulated", "emu"));
    ASSERT_TRUE(c.ok() && c->has_value());
    ASSERT_EQ((*c)->id, id);
    db::TraceChunk ch;
    ch.sample_period_s = 1e-3;
    ch.samples = 100;
    ch.channels = {"i_A"};
    ch.data.assign(100, 0.25);
    ASSERT_TRUE(store_->AppendTraceChunk(vb::db::testing::CurrentLease(store_, id), ch).ok());
    ASSERT_TRUE(store_->Finish(vb::db::testing::CurrentLease(store_, id), db::RunStatus::kDone, "", {{"rmse_A", 0.01}}).ok());
  }
  bool Exists(std::int64_t id) { return store_->GetRun(id).ok(); }

  std::string dir_, db_path_;
  std::unique_ptr<db::Store> store_;
};

TEST_F(RetentionSchedulerTest, PrunesAtTheCronFireKeepingQueuedRunsAndTheNightsBaselineBatch) {
  std::int64_t old_batch = 0, baseline_batch = 0, queued_batch = 0;
  const std::int64_t old_run = Submit("old", &old_batch);
  const std::int64_t baseline_run = Submit("baseline", &baseline_batch);
  const std::int64_t queued_run = Submit("queued", &queued_batch);
  Finish(old_run);
  Finish(baseline_run);
  // The nights' baseline file was taken from baseline_batch on this server.
  const std::string baseline_path = dir_ + "/baseline.json";
  nlohmann::json b = nlohmann::json::parse(std::ifstream(std::string(VB_SOURCE_DIR) + "/examples/suites/ci-baseline.json"));
  b["source"] = "suite ci (server lab:50051 batch " + std::to_string(baseline_batch) + ", seed 1)";
  const std::string baseline_text = b.dump(2);
  std::ofstream(baseline_path) << baseline_text;

  // The injected clock: just before the first 03:30 UTC that is 200 days from now, advancing with real time,
  // so both runs (finished now) are 200 days old at the fire.
  const double now_s = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  auto cron = regress::Cron::Parse("30 3 * * *");
  ASSERT_TRUE(cron.ok());
  auto fire = cron->NextUnix(now_s + 200 * kDay_s, true);
  ASSERT_TRUE(fire.ok());
  const double lead_s = 3.0;
  const auto t0 = std::chrono::steady_clock::now();
  auto clock = [&, fire_s = *fire] {
    return fire_s - lead_s + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };

  server::RetentionSetup setup;
  setup.enabled = true;
  setup.older_than_days = 90;
  setup.keep_last = 0;
  server::NightsSetup nights;
  nights.baseline_path = baseline_path;
  server::StorePool pool(db_path_);
  server::RetentionScheduler scheduler(setup, nights, &pool, clock);

  // Unreadable baseline file: nobody can tell which batch to protect, so nothing is deleted.
  std::filesystem::remove(baseline_path);
  auto refused = scheduler.RunOnce(*fire);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("nights.baseline_file"), std::string::npos) << refused.status().message();
  EXPECT_TRUE(Exists(old_run));
  std::ofstream(baseline_path) << baseline_text;

  scheduler.Start();
  // Before the fire nothing happens (the clock is still lead_s short of 03:30).
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  if (clock() < *fire) {
    EXPECT_TRUE(Exists(old_run)) << "pruned before the cron fire";
  }
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (Exists(old_run) && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  scheduler.Stop();

  EXPECT_FALSE(Exists(old_run)) << "the scheduled prune did not delete the old finished run";
  EXPECT_EQ(store_->GetRun(old_run).status().code(), StatusCode::kNotFound);
  ASSERT_TRUE(Exists(baseline_run)) << "the nights' baseline batch was pruned";
  auto trace = store_->ReadTrace(baseline_run);
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  auto queued = store_->GetRun(queued_run);
  ASSERT_TRUE(queued.ok()) << "the queued run was pruned";
  EXPECT_EQ(queued->status, db::RunStatus::kQueued);

  // The same rule run directly reports what it did: nothing more is old enough to go.
  auto again = scheduler.RunOnce(*fire);
  ASSERT_TRUE(again.ok()) << again.status().message();
  EXPECT_TRUE(again->deleted.empty());
  bool baseline_kept = false;
  for (const auto& d : again->kept)
    if (d.run_id == baseline_run) baseline_kept = d.why.find("nights' baseline file") != std::string::npos;
  EXPECT_TRUE(baseline_kept);
}

// keep_last and older_than_days are what the scheduler passes on: a run younger than the cutoff stays, and with
// keep_last 1 the newest old run stays too.
TEST_F(RetentionSchedulerTest, RunOnceHonoursTheAgeAndKeepLast) {
  std::int64_t b1 = 0, b2 = 0;
  const std::int64_t r1 = Submit("one", &b1);
  const std::int64_t r2 = Submit("two", &b2);
  Finish(r1);
  Finish(r2);
  const double now_s = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  server::RetentionSetup setup;
  setup.enabled = true;
  setup.older_than_days = 90;
  setup.keep_last = 1;
  server::StorePool pool(db_path_);
  server::RetentionScheduler scheduler(setup, server::NightsSetup{}, &pool);

  auto young = scheduler.RunOnce(now_s + 10 * kDay_s);  // 10 days after they finished: too young
  ASSERT_TRUE(young.ok()) << young.status().message();
  EXPECT_TRUE(young->deleted.empty());
  EXPECT_TRUE(Exists(r1) && Exists(r2));

  auto old = scheduler.RunOnce(now_s + 100 * kDay_s);
  ASSERT_TRUE(old.ok()) << old.status().message();
  ASSERT_EQ(old->deleted.size(), 1u);
  EXPECT_EQ(old->deleted[0].run_id, r1);
  EXPECT_GT(old->trace_bytes, 0);
  EXPECT_FALSE(Exists(r1));
  EXPECT_TRUE(Exists(r2));  // the newest one
}

}  // namespace
}  // namespace vb
