// practice4 (../shared/gapbench/practice4, issue 35): moving valves drawn from a population, checked within the CI
// budget on the cases that are cheap to run; perf/perf_identify.cc runs all twenty and prints the rates. Skipped
// when the set is missing. labels.json is read for scoring only; valves.json (the truth) is never read.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <utility>

#include "common/status.h"
#include "gap/dataset.h"
#include "gap/diagnose.h"
#include "gap/moving_valve.h"
#include "model/params.h"

namespace vb::gap {
namespace {

namespace fs = std::filesystem;

const fs::path kPractice4 = fs::path(VB_SHARED_DIR) / "gapbench" / "practice4";

model::PlantParams Family() { return *model::Preset("taghizadeh2009"); }

// A withheld case's two sessions.
struct Sessions {
  Dataset reference, target;
};
StatusOr<Sessions> LoadWithheld(const fs::path& dir) {
  auto target = LoadDataset((dir / "target").string(), model::PresetNames());
  if (!target.ok()) return target.status();
  auto reference = LoadDataset((dir / "reference").string(), model::PresetNames());
  if (!reference.ok()) return reference.status();
  return Sessions{std::move(*reference), std::move(*target)};
}

// The criterion: the holdout runs (6 bar, 0.75x supply) within max(5 mA, 3x the noise floor). Before issue
// 35 this valve was identified at 38 mA RMS on its fit runs (a wrong basin: the edge's eddy transient read as the
// plunger's arrival, and no global stage) and predicted at 43 mA.
TEST(Practice4, P41_0IdentifiedFromScratchPredictsItsHoldoutRuns) {
  const fs::path dir = kPractice4 / "p41_0_predict";
  if (!fs::is_directory(dir)) GTEST_SKIP() << dir << " is missing";
  auto ds = LoadDataset(dir.string(), model::PresetNames());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  auto id = IdentifyMovingValve(*ds, Family());
  ASSERT_TRUE(id.ok()) << id.status().message();
  const double limit = std::max(5e-3, 3.0 * id->noise_floor_A);
  EXPECT_LT(id->fit_rmse_A, limit);
  EXPECT_LT(id->holdout_rmse_after_A, limit);
  for (const auto& r : id->landmarks) EXPECT_EQ(r.measured.pulls_in, r.predicted.pulls_in) << r.run;
  // The edge's transient is not a pull-in: every fit run's measured pull-in lies after the first millisecond.
  for (const auto& r : id->landmarks)
    if (r.measured.pulls_in) {
      EXPECT_GT(r.measured.pull_in_s, 1e-3) << r.run;
    }
}

// A false all-clear is a defect: with a reference the method has not identified (here on purpose: a budget of 600
// evaluations ends the search in stage 2), the verdict is never `none`; when nothing is seen it is `undetermined` with the
// reference's error, the smallest visible change and what to record.
TEST(Practice4, NoneNeverStandsOnAReferenceThatIsNotIdentified) {
  const fs::path dir = kPractice4 / "p41_4_none";
  if (!fs::is_directory(dir)) GTEST_SKIP() << dir << " is missing";
  auto s = LoadWithheld(dir);
  ASSERT_TRUE(s.ok()) << s.status().message();
  DiagnoseOptions o;
  o.reference = &s->reference;
  o.reference_fit.scratch_max_evaluations = 600;
  o.budget_s = 15.0;
  auto d = Diagnose(s->target, Family(), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  ASSERT_TRUE(d->has_reference);
  EXPECT_GT(d->reference.noise_floor_A, 0.0);
  // The budget is a count, so this holds on any machine: 600 evaluations do not identify this valve.
  ASSERT_FALSE(d->reference.identified()) << "reference fit " << d->reference.fit_rmse_A << " A";
  EXPECT_NE(d->verdict_kind, VerdictKind::kNone) << d->verdict << ": " << d->verdict_reason;
  if (d->verdict_kind == VerdictKind::kUndetermined) {
    EXPECT_EQ(d->verdict, "undetermined");
    EXPECT_NE(d->verdict_reason.find("cannot tell"), std::string::npos) << d->verdict_reason;
    EXPECT_TRUE(std::isfinite(d->smallest_visible_A) && d->smallest_visible_A > 0.0);
    EXPECT_FALSE(d->reference.to_record.empty());
    const std::string json = DiagnosisJson(*d);
    EXPECT_NE(json.find("\"verdict_kind\": \"undetermined\""), std::string::npos);
    EXPECT_NE(json.find("\"smallest_visible_A\""), std::string::npos);
  }
}

// A plunger that no longer moves is named `stuck`, not the force that could hold it. No run of p41_3's target dips
// where its reference's valve dips; the best row against that reference (identified at 1.4x its noise) was
// `param:k+supply_voltage+sensor_gain`: a stiffer spring, with the supply and the sense gain matching the current
// at rest through the reference's parameters. What holds a plunger leaves the same current at rest, so the
// current cannot name it (gap/moving_valve.cc, PreferDeterminedChange).
TEST(Practice4, AValveWhoseRunsNoLongerDipIsNamedStuck) {
  const fs::path dir = kPractice4 / "p41_3_stuck";
  if (!fs::is_directory(dir)) GTEST_SKIP() << dir << " is missing";
  auto s = LoadWithheld(dir);
  ASSERT_TRUE(s.ok()) << s.status().message();
  DiagnoseOptions o;
  o.reference = &s->reference;
  auto d = Diagnose(s->target, Family(), o);
  ASSERT_TRUE(d.ok()) << d.status().message();
  ASSERT_TRUE(d->has_reference);
  for (const auto& lm : d->landmarks) {
    EXPECT_FALSE(std::isfinite(lm.dip_t_s[0])) << lm.run << ": the target's runs do not dip";
    EXPECT_TRUE(std::isfinite(lm.dip_t_s[1])) << lm.run << ": the reference's valve dips";
  }
  EXPECT_EQ(d->verdict, "stuck") << d->verdict_reason;
  EXPECT_NE(d->verdict_reason.find("the current cannot name it"), std::string::npos) << d->verdict_reason;
}

}  // namespace
}  // namespace vb::gap
