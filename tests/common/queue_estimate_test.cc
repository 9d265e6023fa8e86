// The queue estimate `benchctl queue` and the web dashboard share (common/queue_estimate.h).
#include "common/queue_estimate.h"

#include <gtest/gtest.h>

namespace vb {
namespace {

TEST(QueueEstimate, PositionsFollowTheClaimOrderAndEtasAddUpOverTheLiveBenches) {
  const std::vector<QueueRunInfo> runs = {
      {1, RunStatus::kRunning, 0, 10.0, 0.5, 100.0},  // 5 s of bench time left
      {2, RunStatus::kQueued, 0, 4.0, 0.0, 0.0},
      {3, RunStatus::kQueued, 5, 2.0, 0.0, 0.0},      // higher priority: claimed first
      {4, RunStatus::kQueued, 0, 6.0, 0.0, 0.0},
  };
  const auto e = EstimateQueue(runs, 2);
  ASSERT_EQ(e.size(), 3u);
  EXPECT_EQ(e.at(3).position, 1);
  EXPECT_EQ(e.at(2).position, 2);
  EXPECT_EQ(e.at(4).position, 3);
  EXPECT_DOUBLE_EQ(e.at(3).eta_s, (5.0 + 2.0) / 2);
  EXPECT_DOUBLE_EQ(e.at(2).eta_s, (5.0 + 2.0 + 4.0) / 2);
  EXPECT_DOUBLE_EQ(e.at(4).eta_s, (5.0 + 2.0 + 4.0 + 6.0) / 2);
}

TEST(QueueEstimate, UnknownWithoutLiveBenchesOrWithoutADuration) {
  const std::vector<QueueRunInfo> runs = {{2, RunStatus::kQueued, 0, 4.0, 0.0, 0.0},
                                          {3, RunStatus::kQueued, 0, 0.0, 0.0, 0.0},
                                          {4, RunStatus::kQueued, 0, 1.0, 0.0, 0.0}};
  EXPECT_LT(EstimateQueue(runs, 0).at(2).eta_s, 0.0) << "no live bench: no ETA";
  const auto e = EstimateQueue(runs, 1);
  EXPECT_DOUBLE_EQ(e.at(2).eta_s, 4.0);
  EXPECT_LT(e.at(3).eta_s, 0.0) << "a run without a duration, and every run after it, has no ETA";
  EXPECT_LT(e.at(4).eta_s, 0.0);
}

TEST(QueueEstimate, ARunningRunsWallTimeLeftFromItsProgress) {
  const QueueRunInfo r{1, RunStatus::kRunning, 0, 10.0, 0.25, 100.0};
  EXPECT_DOUBLE_EQ(RunningEta_s(r, 104.0), 12.0);  // 4 s for a quarter: 12 s for the rest
  EXPECT_LT(RunningEta_s({1, RunStatus::kRunning, 0, 10.0, 0.0, 100.0}, 104.0), 0.0);
  EXPECT_LT(RunningEta_s({1, RunStatus::kQueued, 0, 10.0, 0.5, 0.0}, 104.0), 0.0);
}

}  // namespace
}  // namespace vb
