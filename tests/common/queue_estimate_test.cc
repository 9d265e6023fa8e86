// The queue estimate `benchctl queue` and the web dashboard share (common/queue_estimate.h).
#include "common/queue_estimate.h"

#include <gtest/gtest.h>

namespace vb {
namespace {

// The claims replayed (not the bench time spread evenly, as before issue 37): the free bench takes the next run.
TEST(QueueEstimate, PositionsFollowTheClaimOrderAndEtasReplayTheClaims) {
  const std::vector<QueueRunInfo> runs = {
      {1, RunStatus::kRunning, 0, 10.0, 0.5, 100.0, "", ""},  // 5 s of bench time left on one bench
      {2, RunStatus::kQueued, 0, 4.0, 0.0, 0.0, "", ""},
      {3, RunStatus::kQueued, 5, 2.0, 0.0, 0.0, "", ""},      // higher priority: claimed first
      {4, RunStatus::kQueued, 0, 6.0, 0.0, 0.0, "", ""},
  };
  const auto e = EstimateQueue(runs, 2);
  ASSERT_EQ(e.size(), 3u);
  EXPECT_EQ(e.at(3).position, 1);
  EXPECT_EQ(e.at(2).position, 2);
  EXPECT_EQ(e.at(4).position, 3);
  EXPECT_DOUBLE_EQ(e.at(3).eta_s, 2.0);        // the idle bench takes it at once
  EXPECT_DOUBLE_EQ(e.at(2).eta_s, 2.0 + 4.0);  // then the same bench, free at 2 s before the other at 5 s
  EXPECT_DOUBLE_EQ(e.at(4).eta_s, 5.0 + 6.0);  // the first bench, once its running run is over
}

// Issue 37: a taghizadeh2009 run queued behind lunge2013 runs, on a lab with one bench of each, waits only for
// the taghizadeh2009 bench; a run no live bench can run has no ETA; a run naming a bench waits for that one.
TEST(QueueEstimate, OnlyBenchesThatCanRunTheSpecCount) {
  std::vector<QueueRunInfo> runs = {
      {1, RunStatus::kRunning, 0, 40.0, 0.5, 100.0, "emulated:taghizadeh2009", "taghi"},  // 20 s left
      {2, RunStatus::kQueued, 0, 30.0, 0.0, 0.0, "emulated:lunge2013", ""},
      {3, RunStatus::kQueued, 0, 30.0, 0.0, 0.0, "emulated:lunge2013", ""},
      {4, RunStatus::kQueued, 0, 57.0, 0.0, 0.0, "emulated:taghizadeh2009", ""},
      {5, RunStatus::kQueued, 0, 1.0, 0.0, 0.0, "hid", ""},
      {6, RunStatus::kQueued, 0, 2.0, 0.0, 0.0, "emulated:lunge2013", "lunge-b"},
  };
  const std::vector<QueueBench> benches = {{"taghi", "emulated:taghizadeh2009", true, false},
                                           {"lunge", "emulated:lunge2013", true, false},
                                           {"lunge-b", "emulated:lunge2013", false, false}};  // not alive
  const auto e = EstimateQueue(runs, benches);
  EXPECT_DOUBLE_EQ(e.at(2).eta_s, 30.0);
  EXPECT_DOUBLE_EQ(e.at(3).eta_s, 60.0);
  EXPECT_DOUBLE_EQ(e.at(4).eta_s, 20.0 + 57.0);  // not (20 + 30 + 30 + 57) / 2 = 68.5 over both benches
  EXPECT_LT(e.at(5).eta_s, 0.0) << "no hid bench";
  EXPECT_LT(e.at(6).eta_s, 0.0) << "its bench is not alive";
  EXPECT_EQ(e.at(4).position, 3);
  // The local emulator takes every spec.
  const auto local = EstimateQueue(runs, {{"local", "local", true, true}});
  EXPECT_DOUBLE_EQ(local.at(5).eta_s, 30.0 + 30.0 + 57.0 + 1.0);
}

TEST(QueueEstimate, UnknownWithoutLiveBenchesOrWithoutADuration) {
  const std::vector<QueueRunInfo> runs = {{2, RunStatus::kQueued, 0, 4.0, 0.0, 0.0, "", ""},
                                          {3, RunStatus::kQueued, 0, 0.0, 0.0, 0.0, "", ""},
                                          {4, RunStatus::kQueued, 0, 1.0, 0.0, 0.0, "", ""}};
  EXPECT_LT(EstimateQueue(runs, 0).at(2).eta_s, 0.0) << "no live bench: no ETA";
  const auto e = EstimateQueue(runs, 1);
  EXPECT_DOUBLE_EQ(e.at(2).eta_s, 4.0);
  EXPECT_LT(e.at(3).eta_s, 0.0) << "a run without a duration, and every run after it, has no ETA";
  EXPECT_LT(e.at(4).eta_s, 0.0);
}

TEST(QueueEstimate, ARunningRunsWallTimeLeftFromItsProgress) {
  const QueueRunInfo r{1, RunStatus::kRunning, 0, 10.0, 0.25, 100.0, "", ""};
  EXPECT_DOUBLE_EQ(RunningEta_s(r, 104.0), 12.0);  // 4 s for a quarter: 12 s for the rest
  EXPECT_LT(RunningEta_s({1, RunStatus::kRunning, 0, 10.0, 0.0, 100.0, "", ""}, 104.0), 0.0);
  EXPECT_LT(RunningEta_s({1, RunStatus::kQueued, 0, 10.0, 0.5, 0.0, "", ""}, 104.0), 0.0);
}

}  // namespace
}  // namespace vb
