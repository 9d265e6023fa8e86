#include <gtest/gtest.h>

#include "gap/diagnose.h"

namespace vb::gap {
namespace {

// "Is there a gap, and where" only: attribution has its own tests (attribution_test.cc).
StatusOr<Diagnosis> DiagnosePractice(const std::string& name) {
  auto ds = LoadDataset(std::string(VB_SHARED_DIR) + "/gapbench/practice/" + name);
  if (!ds.ok()) return ds.status();
  DiagnoseOptions opt;
  opt.attribute = false;
  return Diagnose(*ds, *model::Preset("taghizadeh2009"), opt);
}

// Effect-free data gets the verdict "none" (issue 5), and every labelled effect a significant gap.
TEST(Diagnose, NoneOnEffectFreeDataAndSignificantOtherwise) {
  for (const char* set : {"p10", "p12"}) {
    auto d = DiagnosePractice(set);
    if (!d.ok()) GTEST_SKIP() << d.status().message();
    EXPECT_EQ(d->verdict, "none") << set;
    EXPECT_FALSE(d->significant) << set;
    EXPECT_NEAR(d->noise_floor_A, 2.0e-3, 0.3e-3) << set;
  }
  for (const char* set : {"p01", "p02", "p03", "p04", "p05", "p06", "p07", "p08", "p09", "p11"}) {
    auto d = DiagnosePractice(set);
    if (!d.ok()) GTEST_SKIP() << d.status().message();
    EXPECT_TRUE(d->significant) << set;
    EXPECT_NE(d->verdict, "none") << set;
  }
}

// Where: supply resistance lives in the energised hold; friction in the moving phases.
TEST(Diagnose, LocalisesTheGapByPhase) {
  auto p07 = DiagnosePractice("p07");
  if (!p07.ok()) GTEST_SKIP() << p07.status().message();
  ASSERT_FALSE(p07->where.empty());
  EXPECT_EQ(p07->where.front().phase, Phase::kOpen);
  auto p02 = DiagnosePractice("p02");
  ASSERT_TRUE(p02.ok());
  double moving = 0.0;
  for (const auto& w : p02->where)
    if (w.phase == Phase::kOpening || w.phase == Phase::kClosing) moving += w.share;
  EXPECT_GT(moving, 0.5);
  const std::string json = DiagnosisJson(*p07);
  for (const char* key : {"\"model\"", "\"noise_floor_A\"", "\"gap\"", "\"fit_rmse_A\"", "\"holdout_rmse_A\"",
                          "\"significant\"", "\"where\"", "\"ranking\"", "\"verdict\""})
    EXPECT_NE(json.find(key), std::string::npos) << key;
}

}  // namespace
}  // namespace vb::gap
