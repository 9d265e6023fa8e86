// One formatter each way for the vocabularies that used to travel as text (issue 27, point 3).
#include <gtest/gtest.h>

#include "common/bench_kind.h"
#include "common/run_status.h"
#include "common/split.h"

namespace vb {
namespace {

TEST(Enums, BenchKindsRoundTripAndUnknownOnesNameTheField) {
  for (BenchKind k : {BenchKind::kEmulated, BenchKind::kHid, BenchKind::kU3}) {
    auto back = ParseBenchKind(BenchKindName(k));
    ASSERT_TRUE(back.ok());
    EXPECT_EQ(*back, k);
  }
  EXPECT_EQ(*ParseBenchKind(""), BenchKind::kEmulated) << "the default";
  const Status bad = ParseBenchKind("usb", "benches[2].kind").status();
  EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.message(), "benches[2].kind: unknown bench kind 'usb' (known: emulated, hid, u3)");
  EXPECT_FALSE(ParseBenchKind("HID").ok()) << "names are exact";
}

TEST(Enums, SplitsRoundTripAndOthersAreRefused) {
  for (Split s : {Split::kNone, Split::kFit, Split::kHoldout}) {
    auto back = ParseSplit(SplitName(s));
    ASSERT_TRUE(back.ok());
    EXPECT_EQ(*back, s);
  }
  EXPECT_STREQ(SplitName(Split::kHoldout), "holdout");
  const Status bad = ParseSplit("train").status();
  EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.message(), "'train' is not fit or holdout");
  EXPECT_FALSE(ParseSplit("Fit").ok());
}

TEST(Enums, RunOutcomesRoundTrip) {
  for (RunStatus s : {RunStatus::kQueued, RunStatus::kRunning, RunStatus::kDone, RunStatus::kFailed,
                      RunStatus::kCancelled, RunStatus::kInterrupted}) {
    auto back = ParseRunStatus(RunStatusName(s));
    ASSERT_TRUE(back.ok());
    EXPECT_EQ(*back, s);
  }
  EXPECT_FALSE(ParseRunStatus("ok").ok());
}

}  // namespace
}  // namespace vb
