// PlanPrune (db/prune_plan.h): the retention rules on facts alone, without a database. Each rule has a test
// that fails if it breaks; tests/db/prune_test.cc checks that both engines execute the plan.
#include <gtest/gtest.h>

#include <algorithm>

#include "db/prune_plan.h"
#include "db/text.h"

namespace vb::db {
namespace {

constexpr double kCutoff = 1'000'000.0;

PruneFacts::Run Old(std::int64_t id, std::int64_t batch, RunStatus status = RunStatus::kDone) {
  return {id, batch, Cat("r", id), status, kCutoff - 10.0};
}

PruneRequest Request(std::int32_t keep_last = 0) {
  PruneRequest r;
  r.finished_before_unix_s = kCutoff;
  r.keep_last = keep_last;
  return r;
}

const PruneDecision* Find(const std::vector<PruneDecision>& v, std::int64_t id) {
  for (const auto& d : v)
    if (d.run_id == id) return &d;
  return nullptr;
}

TEST(PrunePlanTest, OldFinishedRunsGoNewestFirstAndTheirEmptyBatchesWithThem) {
  PruneFacts f;
  f.runs = {Old(1, 1), Old(2, 1, RunStatus::kFailed), Old(3, 2, RunStatus::kCancelled), Old(4, 2)};
  f.runs[3].finished_unix_s = kCutoff;  // not before the cutoff: stays (counted, not listed)
  const PrunePlan p = PlanPrune(f, Request());
  EXPECT_EQ(p.doomed, (std::vector<std::int64_t>{3, 2, 1}));
  EXPECT_EQ(p.result.newer_kept, 1);
  EXPECT_TRUE(p.result.kept.empty());
  EXPECT_EQ(p.empty_batches, (std::vector<std::int64_t>{1})) << "batch 2 keeps run 4";
  EXPECT_EQ(p.result.batches_deleted, 1);
  ASSERT_EQ(p.result.deleted.size(), 3u);
  EXPECT_NE(p.result.deleted[0].why.find("cancelled, finished"), std::string::npos) << p.result.deleted[0].why;
  EXPECT_NE(p.result.deleted[0].why.find("before the cutoff"), std::string::npos);
}

TEST(PrunePlanTest, UnfinishedRunsAreNeverPrunedWhateverTheirAge) {
  PruneFacts f;
  f.runs = {Old(1, 1, RunStatus::kQueued), Old(2, 1, RunStatus::kRunning), Old(3, 1, RunStatus::kInterrupted),
            Old(4, 1)};
  const PrunePlan p = PlanPrune(f, Request());
  EXPECT_EQ(p.doomed, (std::vector<std::int64_t>{4}));
  EXPECT_EQ(p.result.kept.size(), 3u);
  for (std::int64_t id : {1, 2, 3}) {
    const PruneDecision* d = Find(p.result.kept, id);
    ASSERT_NE(d, nullptr) << id;
    EXPECT_NE(d->why.find("only finished runs are pruned"), std::string::npos) << d->why;
  }
  EXPECT_TRUE(p.empty_batches.empty()) << "the batch keeps its unfinished runs";
}

TEST(PrunePlanTest, KeepLastKeepsTheNewestFinishedRunsByIdInOrderGiven) {
  PruneFacts f;
  f.runs = {Old(5, 1), Old(1, 1), Old(4, 1, RunStatus::kQueued), Old(3, 1), Old(2, 1)};  // any order
  const PrunePlan p = PlanPrune(f, Request(2));
  EXPECT_EQ(p.doomed, (std::vector<std::int64_t>{2, 1})) << "5 and 3 are the newest two finished runs";
  const PruneDecision* d = Find(p.result.kept, 3);
  ASSERT_NE(d, nullptr);
  EXPECT_NE(d->why.find("one of the newest 2 finished runs"), std::string::npos) << d->why;
}

TEST(PrunePlanTest, NewerRunsCountTowardsKeepLast) {
  PruneFacts f;
  f.runs = {Old(1, 1), Old(2, 1)};
  f.runs[1].finished_unix_s = kCutoff + 5;
  const PrunePlan p = PlanPrune(f, Request(1));
  EXPECT_EQ(p.doomed, (std::vector<std::int64_t>{1})) << "run 2 is the newest finished run and is kept as newer";
  EXPECT_EQ(p.result.newer_kept, 1);
}

TEST(PrunePlanTest, ReferencedBatchesAreKeptSayingWhatReferencesThem) {
  PruneFacts f;
  f.runs = {Old(1, 1), Old(2, 2), Old(3, 3), Old(4, 4), Old(5, 5)};
  f.regressions = {{7, 1, "", "ci", {}}, {8, 2, "2026-11-20", "nightly", {}}, {9, 0, "", "remote", {}}};
  f.baselines = {{"main", 3, "local batch 3"}, {"other", 1, "server lab:50051 batch 4"}};
  PruneRequest req = Request();
  req.protected_batches = {5};
  req.protected_why = "the server's baseline 'night' v2";
  const PrunePlan p = PlanPrune(f, req);
  EXPECT_EQ(p.doomed, (std::vector<std::int64_t>{4})) << "a server baseline source is not a local batch";
  EXPECT_NE(Find(p.result.kept, 1)->why.find("regression result 7 (suite ci) references batch 1"), std::string::npos);
  EXPECT_NE(Find(p.result.kept, 2)->why.find("regression night 2026-11-20 (result 8)"), std::string::npos);
  EXPECT_NE(Find(p.result.kept, 3)->why.find("baseline 'main' v3 references batch 3"), std::string::npos);
  EXPECT_NE(Find(p.result.kept, 5)->why.find("the server's baseline 'night' v2"), std::string::npos);
}

// A night's health checks are kept with it: after a restart the bench twin identifies its anchor (the first
// check) and the baseline's night again from their runs, and `benchctl health --recompute` reads them all.
TEST(PrunePlanTest, ANightsHealthChecksAreKeptWithIt) {
  EXPECT_EQ(HealthBatchesOfNight(R"({"health": [{"bench": "a", "batch_id": 12}, {"bench": "b", "error": "x"},
                                              {"bench": "c", "batch_id": 14}]})"),
            (std::vector<std::int64_t>{12, 14}));
  EXPECT_TRUE(HealthBatchesOfNight("").empty());
  EXPECT_TRUE(HealthBatchesOfNight("not json").empty());
  EXPECT_TRUE(HealthBatchesOfNight(R"({"health": {"batch_id": 3}})").empty());
  EXPECT_TRUE(HealthBatchesOfNight(R"({"health": [{"batch_id": "3"}, {"batch_id": -2}, {"batch_id": 1.5}]})").empty());

  PruneFacts f;
  f.runs = {Old(1, 11), Old(2, 12), Old(3, 13), Old(4, 14)};
  f.regressions = {{8, 13, "2026-11-20", "nightly", HealthBatchesOfNight(R"({"health": [{"batch_id": 12}]})")}};
  const PrunePlan p = PlanPrune(f, Request());
  EXPECT_EQ(p.doomed, (std::vector<std::int64_t>{4, 1})) << "batches 11 and 14 are nobody's";
  ASSERT_NE(Find(p.result.kept, 2), nullptr);
  EXPECT_NE(Find(p.result.kept, 2)->why.find("the health check of regression night 2026-11-20 (result 8) references "
                                             "batch 12"),
            std::string::npos)
      << Find(p.result.kept, 2)->why;
  EXPECT_NE(Find(p.result.kept, 3)->why.find("regression night 2026-11-20"), std::string::npos);
}

TEST(PrunePlanTest, TheRulesApplyInOrderNewerThenReferencedThenKeepLast) {
  PruneFacts f;
  f.runs = {Old(1, 1), Old(2, 2)};
  f.regressions = {{1, 2, "", "ci", {}}};
  const PrunePlan p = PlanPrune(f, Request(1));
  // Run 2 is both the newest finished run and referenced: the reference is the reason given.
  EXPECT_NE(Find(p.result.kept, 2)->why.find("regression result 1"), std::string::npos);
  EXPECT_EQ(p.doomed, (std::vector<std::int64_t>{1})) << "run 2 used up keep_last=1";
}

TEST(PrunePlanTest, NoRunsNoPlan) {
  const PrunePlan p = PlanPrune(PruneFacts{}, Request(3));
  EXPECT_TRUE(p.doomed.empty());
  EXPECT_TRUE(p.result.kept.empty());
  EXPECT_EQ(p.result.batches_deleted, 0);
}

}  // namespace
}  // namespace vb::db
