// Retention (Store::Prune, docs/store.md "Retention"): each rule with a test that fails if the rule breaks —
// old finished runs go with everything they own; queued, running and interrupted runs, runs a baseline or a
// regression result references, the newest N and runs newer than the cutoff stay; a dry run deletes nothing;
// bad requests name the field.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <set>

#include "db/store.h"
#include "db/testing.h"
#include "db/text.h"
#include "tests/db/store_engines.h"

namespace vb::db {
namespace {

constexpr double kDay = 86400.0;

// On both engines (tests/db/store_engines.h).
class PruneTest : public testing::StoreEngineTest {
 protected:
  void SetUp() override {
    StoreEngineTest::SetUp();
    now_ = static_cast<double>(std::time(nullptr));
  }

  // A batch of `n` runs; returns their ids. The batch id goes to *batch.
  std::vector<std::int64_t> Batch(int n, std::int64_t* batch = nullptr) {
    std::vector<RunRecord> runs;
    for (int k = 0; k < n; ++k) {
      RunRecord r;
      r.key = NamedRun(Cat("r", next_name_++));
      r.controller = "pi_current";
      r.bench_kind = "emulated";
      r.spec_json = "{}";
      r.tags = {"t"};
      runs.push_back(r);
    }
    std::vector<std::int64_t> ids;
    auto b = store_->SubmitBatch("alice", "b", "{}", runs, &ids);
    EXPECT_TRUE(b.ok()) << b.status().ToString();
    if (batch != nullptr) *batch = b.ok() ? *b : 0;
    return ids;
  }
  // Claims, traces and finishes run `id`, then sets its finish time to `days_ago` days before now.
  void FinishAged(std::int64_t id, double days_ago, RunStatus status = RunStatus::kDone) {
    auto c = store_->ClaimNext(db::BenchClaim("emulated", "bench-1"));
    ASSERT_TRUE(c.ok() && c->has_value());
    ASSERT_EQ((*c)->id, id) << "runs are claimed in id order in these tests";
    TraceChunk ch;
    ch.sample_period_s = 1e-3;
    ch.samples = 100;
    ch.channels = {"i_A"};
    ch.data.assign(100, 0.25);
    ASSERT_TRUE(store_->AppendTraceChunk(vb::db::testing::CurrentLease(store_, id), ch).ok());
    ASSERT_TRUE(store_->Finish(vb::db::testing::CurrentLease(store_, id), status, "", {{"rmse_A", 0.01}}).ok());
    Exec(Cat("UPDATE runs SET finished = ", static_cast<std::int64_t>(now_ - days_ago * kDay), " WHERE id = ", id));
  }
  void Exec(const std::string& sql) { RawExec(sql); }
  std::int64_t Count(const std::string& sql) { return RawInt(sql); }
  PruneResult Prune(double older_than_days, int keep_last = 0, bool dry_run = false) {
    PruneRequest req;
    req.finished_before_unix_s = now_ - older_than_days * kDay;
    req.keep_last = keep_last;
    req.dry_run = dry_run;
    auto r = store_->Prune(req);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? *r : PruneResult{};
  }
  static std::set<std::int64_t> Ids(const std::vector<PruneDecision>& v) {
    std::set<std::int64_t> out;
    for (const auto& d : v) out.insert(d.run_id);
    return out;
  }
  static const PruneDecision* Find(const std::vector<PruneDecision>& v, std::int64_t id) {
    for (const auto& d : v)
      if (d.run_id == id) return &d;
    return nullptr;
  }

  double now_ = 0;
  int next_name_ = 0;
};

TEST_P(PruneTest, DeletesOldFinishedRunsWithEverythingTheyOwnAndTheirEmptyBatch) {
  std::int64_t old_batch = 0, mixed_batch = 0;
  auto old = Batch(2, &old_batch);
  auto mixed = Batch(2, &mixed_batch);
  FinishAged(old[0], 40);
  FinishAged(old[1], 35, RunStatus::kFailed);
  FinishAged(mixed[0], 31, RunStatus::kCancelled);
  FinishAged(mixed[1], 2);  // new: stays, and so does its batch
  const PruneResult r = Prune(30);
  EXPECT_EQ(Ids(r.deleted), (std::set<std::int64_t>{old[0], old[1], mixed[0]}));
  EXPECT_EQ(r.newer_kept, 1);
  EXPECT_EQ(r.batches_deleted, 1);
  EXPECT_GT(r.trace_bytes, 0);
  EXPECT_NE(Find(r.deleted, old[0])->why.find("before the cutoff"), std::string::npos) << Find(r.deleted, old[0])->why;
  for (std::int64_t id : {old[0], old[1], mixed[0]}) {
    EXPECT_EQ(store_->GetRun(id).status().code(), StatusCode::kNotFound) << id;
    for (const char* table : {"trace_chunks", "metrics", "status_history", "run_tags"})
      EXPECT_EQ(Count(Cat("SELECT count(*) FROM ", table, " WHERE run_id = ", id)), 0) << table << " of run " << id;
  }
  EXPECT_EQ(Count(Cat("SELECT count(*) FROM batches WHERE id = ", old_batch)), 0);
  EXPECT_EQ(Count(Cat("SELECT count(*) FROM batches WHERE id = ", mixed_batch)), 1);
  auto kept = store_->ReadTrace(mixed[1]);
  ASSERT_TRUE(kept.ok());
  EXPECT_EQ(kept->size(), 1u);
  // SQLite checks foreign keys only when asked; PostgreSQL would have refused the DELETE.
  if (!postgres()) {
    EXPECT_EQ(Count("SELECT count(*) FROM pragma_foreign_key_check"), 0);
  }
}

TEST_P(PruneTest, NeverTouchesQueuedRunningOrInterruptedRuns) {
  auto ids = Batch(4);
  FinishAged(ids[0], 100);
  ASSERT_TRUE(store_->ClaimNext(db::BenchClaim("emulated", "bench-1")).ok());  // ids[1] running
  // ids[2] interrupted (as RecoverAfterCrash leaves a run that may not be re-queued), ids[3] queued; both with
  // old times, so only their status protects them.
  Exec(Cat("UPDATE runs SET status = 'interrupted', submitted = 1, finished = 1 WHERE id = ", ids[2]));
  Exec(Cat("UPDATE runs SET submitted = 1 WHERE id IN (", ids[1], ", ", ids[3], ")"));
  const PruneResult r = Prune(1);
  EXPECT_EQ(Ids(r.deleted), (std::set<std::int64_t>{ids[0]}));
  for (std::int64_t id : {ids[1], ids[2], ids[3]}) {
    const PruneDecision* d = Find(r.kept, id);
    ASSERT_NE(d, nullptr) << id;
    EXPECT_NE(d->why.find("only finished runs are pruned"), std::string::npos) << d->why;
    EXPECT_TRUE(store_->GetRun(id).ok());
  }
  EXPECT_EQ(Find(r.kept, ids[1])->status, RunStatus::kRunning);
}

TEST_P(PruneTest, KeepsRunsOfBatchesABaselineTookFromTheLocalStore) {
  std::int64_t b1 = 0, b2 = 0, b3 = 0;
  auto a = Batch(1, &b1);
  auto b = Batch(1, &b2);
  auto c = Batch(1, &b3);
  FinishAged(a[0], 90);
  FinishAged(b[0], 90);
  FinishAged(c[0], 90);
  const std::vector<BaselineEntry> entries = {{"pi", "rmse", 1e-3, 1e-5, 3}};
  ASSERT_TRUE(store_->SaveBaseline("ci", Cat("local batch ", b1), "", entries).ok());
  ASSERT_TRUE(store_->SaveBaseline("suite", Cat("suite ci (local batch ", b2, ", seed 1)"), "", entries).ok());
  // A baseline from a server's batch with the same number says nothing about this store's batch 3.
  ASSERT_TRUE(store_->SaveBaseline("remote", Cat("server lab:50051 batch ", b3), "", entries).ok());
  const PruneResult r = Prune(30);
  EXPECT_EQ(Ids(r.deleted), (std::set<std::int64_t>{c[0]}));
  ASSERT_NE(Find(r.kept, a[0]), nullptr);
  EXPECT_NE(Find(r.kept, a[0])->why.find("baseline 'ci' v1"), std::string::npos) << Find(r.kept, a[0])->why;
  ASSERT_NE(Find(r.kept, b[0]), nullptr);
  EXPECT_NE(Find(r.kept, b[0])->why.find("baseline 'suite' v1"), std::string::npos);
}

TEST_P(PruneTest, KeepsRunsOfBatchesARegressionNightOrResultReferences) {
  std::int64_t night_batch = 0, manual_batch = 0, free_batch = 0, health_batch = 0;
  auto n = Batch(2, &night_batch);
  auto m = Batch(1, &manual_batch);
  auto f = Batch(1, &free_batch);
  auto h = Batch(1, &health_batch);
  for (std::int64_t id : {n[0], n[1], m[0], f[0], h[0]}) FinishAged(id, 60);
  RegressionRecord night;
  night.suite = "nightly";
  night.baseline_name = "main";
  night.baseline_version = 1;
  night.batch_id = night_batch;
  night.night = "2026-09-01";
  night.verdict = "passed";
  // The night's health check is kept with it (server/nights.cc writes its batch into the result).
  night.result_json = R"({"health": [{"bench": "emu", "batch_id": )" + std::to_string(health_batch) + "}]}";
  ASSERT_TRUE(store_->SaveRegression(night).ok());
  RegressionRecord manual = night;
  manual.night = "";
  manual.batch_id = manual_batch;
  manual.result_json = R"({"health": [{"bench": "emu", "batch_id": )" + std::to_string(free_batch) + "}]}";  // not a night's
  ASSERT_TRUE(store_->SaveRegression(manual).ok());
  const PruneResult r = Prune(30);
  EXPECT_EQ(Ids(r.deleted), (std::set<std::int64_t>{f[0]}));
  ASSERT_NE(Find(r.kept, h[0]), nullptr);
  EXPECT_NE(Find(r.kept, h[0])->why.find("the health check of regression night 2026-09-01"), std::string::npos)
      << Find(r.kept, h[0])->why;
  EXPECT_NE(Find(r.kept, n[0])->why.find("regression night 2026-09-01"), std::string::npos) << Find(r.kept, n[0])->why;
  EXPECT_NE(Find(r.kept, m[0])->why.find("regression result"), std::string::npos);
  EXPECT_TRUE(store_->GetRun(n[1]).ok());
}

TEST_P(PruneTest, KeepLastKeepsTheNewestFinishedRunsAndCallerProtectedBatchesStay) {
  std::int64_t guarded = 0;
  auto g = Batch(1, &guarded);
  auto ids = Batch(5);
  FinishAged(g[0], 50);
  for (int k = 0; k < 5; ++k) FinishAged(ids[k], 50 - k);
  PruneRequest req;
  req.finished_before_unix_s = now_ - 30 * kDay;
  req.keep_last = 2;
  req.protected_batches = {guarded};
  req.protected_why = "the server's baseline 'main' v2";
  auto r = store_->Prune(req);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  // The newest two finished runs (highest ids) stay, however old.
  EXPECT_EQ(Ids(r->deleted), (std::set<std::int64_t>{ids[0], ids[1], ids[2]}));
  EXPECT_NE(Find(r->kept, ids[4])->why.find("newest 2"), std::string::npos);
  EXPECT_NE(Find(r->kept, ids[3])->why.find("newest 2"), std::string::npos);
  EXPECT_NE(Find(r->kept, g[0])->why.find("the server's baseline 'main' v2"), std::string::npos);
}

TEST_P(PruneTest, DryRunReportsTheSameAndDeletesNothing) {
  std::int64_t batch = 0;
  auto ids = Batch(3, &batch);
  for (std::int64_t id : ids) FinishAged(id, 45);
  const std::int64_t bytes_before = Count("SELECT sum(length(data)) FROM trace_chunks");
  const PruneResult dry = Prune(30, 1, /*dry_run=*/true);
  EXPECT_EQ(dry.deleted.size(), 2u);
  EXPECT_EQ(dry.batches_deleted, 0);  // one run stays in it
  EXPECT_EQ(Count("SELECT count(*) FROM runs"), 3);
  EXPECT_EQ(Count("SELECT sum(length(data)) FROM trace_chunks"), bytes_before);
  const PruneResult real = Prune(30, 1);
  EXPECT_EQ(Ids(real.deleted), Ids(dry.deleted));
  EXPECT_EQ(real.trace_bytes, dry.trace_bytes);
  EXPECT_EQ(Count("SELECT count(*) FROM runs"), 1);
  // A dry run that would empty a batch says so.
  const PruneResult all = Prune(30, 0, true);
  EXPECT_EQ(all.batches_deleted, 1);
}

TEST_P(PruneTest, BadRequestsNameTheFieldAndChangeNothing) {
  auto ids = Batch(1);
  FinishAged(ids[0], 40);
  PruneRequest req;
  req.finished_before_unix_s = 0;
  auto r = store_->Prune(req);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("finished_before_unix_s"), std::string::npos);
  req.finished_before_unix_s = now_;
  req.keep_last = -1;
  r = store_->Prune(req);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("keep_last"), std::string::npos);
  req.keep_last = 0;
  req.protected_batches = {0};
  r = store_->Prune(req);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("protected_batches[0]"), std::string::npos);
  EXPECT_TRUE(store_->GetRun(ids[0]).ok());
}

INSTANTIATE_TEST_SUITE_P(Engines, PruneTest, ::testing::ValuesIn(testing::StoreEngines()), testing::EngineName);

TEST(PruneSourceTest, LocalBatchOfBaselineSource) {
  EXPECT_EQ(LocalBatchOfBaselineSource("local batch 12"), 12);
  EXPECT_EQ(LocalBatchOfBaselineSource("suite ci (local batch 7, seed 1)"), 7);
  EXPECT_EQ(LocalBatchOfBaselineSource("server lab:50051 batch 12"), 0);
  EXPECT_EQ(LocalBatchOfBaselineSource("suite ci (server lab:50051 batch 7, seed 1)"), 0);
  EXPECT_EQ(LocalBatchOfBaselineSource("local batch "), 0);
  EXPECT_EQ(LocalBatchOfBaselineSource("nonlocal batch 3"), 0);
  EXPECT_EQ(LocalBatchOfBaselineSource(""), 0);
  EXPECT_EQ(ServerBatchOfBaselineSource("server lab:50051 batch 12"), 12);
  EXPECT_EQ(ServerBatchOfBaselineSource("suite ci (server lab:50051 batch 7, seed 1)"), 7);
  EXPECT_EQ(ServerBatchOfBaselineSource("local batch 12"), 0);
  EXPECT_EQ(ServerBatchOfBaselineSource("server lab:50051 batch x"), 0);
  EXPECT_EQ(ServerBatchOfBaselineSource("server lab batch 99999999999999999999999"), 0) << "overflow is no batch";
}

}  // namespace
}  // namespace vb::db
