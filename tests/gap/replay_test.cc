#include <gtest/gtest.h>

#include <cmath>

#include "../model/perfref.h"
#include "gap/replay.h"

namespace vb::gap {
namespace {

// Replaying E1's gate sequence (sampled at 50 kHz) reproduces the reference solver's current: the edges of a
// 50 Hz, 40 % PWM fall exactly on the sample grid, so the sampled gate loses nothing.
TEST(Replay, ReproducesTheReferenceFromTheSampledGate) {
  ReplayInput in;
  in.supply_V = 24.0;
  in.supply_pressure_Pa = 4e5;
  in.sample_period_s = 2e-5;
  for (int k = 0; k <= 50000; ++k) in.gate.push_back((k % 1000) < 400 ? 1 : 0);
  auto r = ReplayRun(*model::Preset("taghizadeh2009"), model::DriverParams{}, in);
  ASSERT_TRUE(r.ok()) << r.status().message();
  const auto ref = vb::testing::LoadRefTrace("E1");
  ASSERT_EQ(r->i_A.size(), ref.i_A.size());
  double se = 0;
  for (size_t k = 0; k < ref.i_A.size(); ++k) se += std::pow(r->i_A[k] - ref.i_A[k], 2);
  EXPECT_LT(std::sqrt(se / ref.i_A.size()), 1e-8);
  // Every phase occurs in E1, in the right order around the first opening.
  int count[kPhaseCount] = {};
  for (Phase p : r->phase) ++count[static_cast<int>(p)];
  for (int p = 0; p < kPhaseCount; ++p) EXPECT_GT(count[p], 0) << PhaseName(static_cast<Phase>(p));
  EXPECT_EQ(r->phase[50], Phase::kRise);      // 1 ms: energised, not yet lifted (lift at 2.34 ms)
  EXPECT_EQ(r->phase[150], Phase::kOpening);  // 3 ms
  EXPECT_EQ(r->phase[300], Phase::kOpen);     // 6 ms
  EXPECT_EQ(r->phase[450], Phase::kRelease);  // 9 ms: gate off since 8 ms, spool leaves at 17.2 ms
  EXPECT_EQ(r->phase[900], Phase::kClosing);  // 18 ms
}

TEST(Replay, BadInputNamesTheField) {
  ReplayInput in;
  in.gate = {0, 1, 2};
  auto r = ReplayRun(*model::Preset("taghizadeh2009"), model::DriverParams{}, in);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("gate[2]"), std::string::npos);
}

}  // namespace
}  // namespace vb::gap

#include "gap/dataset.h"

namespace vb::gap {
namespace {

// On the effect-free practice datasets (labels.json: p10, p12), replaying every run through the nominal
// model leaves only the acquisition noise: the residual's RMS equals the noise floor estimated from the data
// itself (second differences: sqrt(mean(d2^2)/6) for white noise). An independent simulator made the data,
// so this checks our nominal model against theirs on data nothing was fitted to.
TEST(Replay, NominalModelLeavesOnlyNoiseOnEffectFreePracticeData) {
  for (const char* name : {"p10", "p12"}) {
    const std::string dir = std::string(VB_SHARED_DIR) + "/gapbench/practice/" + name;
    auto ds = LoadDataset(dir);
    if (!ds.ok()) GTEST_SKIP() << ds.status().message();
    double se = 0, d2 = 0;
    size_t n = 0, n2 = 0;
    for (const auto& r : ds->runs) {
      ReplayInput in;
      in.supply_V = r.supply_V;
      in.supply_pressure_Pa = r.supply_pressure_Pa;
      in.sample_period_s = r.sample_period_s;
      in.gate = r.gate;
      auto rep = ReplayRun(*model::Preset("taghizadeh2009"), model::DriverParams{}, in);
      ASSERT_TRUE(rep.ok()) << rep.status().message();
      for (size_t k = 0; k < r.i_A.size(); ++k, ++n) se += std::pow(r.i_A[k] - rep->i_A[k], 2);
      for (size_t k = 2; k < r.i_A.size(); ++k, ++n2) d2 += std::pow(r.i_A[k] - 2 * r.i_A[k - 1] + r.i_A[k - 2], 2);
    }
    const double rms = std::sqrt(se / n), noise = std::sqrt(d2 / n2 / 6.0);
    EXPECT_NEAR(rms, noise, 0.1 * noise) << name;
    EXPECT_LT(rms, 2.5e-3) << name;
  }
}

}  // namespace
}  // namespace vb::gap

namespace vb::gap {
namespace {

std::vector<SessionRun> Session(const Dataset& ds) {
  std::vector<SessionRun> runs;
  for (const auto& r : ds.runs) runs.push_back({r.supply_V, r.supply_pressure_Pa, r.sample_period_s, r.t_start_s, &r.gate});
  return runs;
}

double SessionRms(const Dataset& ds, const model::PlantParams& p) {
  auto reps = ReplaySession(p, model::DriverParams{}, Session(ds));
  EXPECT_TRUE(reps.ok()) << reps.status().message();
  double se = 0;
  size_t n = 0;
  for (size_t r = 0; r < ds.runs.size(); ++r)
    for (size_t k = 0; k < ds.runs[r].i_A.size(); ++k, ++n) se += std::pow(ds.runs[r].i_A[k] - (*reps)[r].i_A[k], 2);
  return std::sqrt(se / n);
}

// Coil heating accumulates over a session: with the temperature carried from run to run (cooling in the idle
// time), our one-node thermal model at the label's values closes p01's 50 mA gap to the noise floor.
TEST(ReplaySession, CarriesTheCoilTemperatureAcrossRuns) {
  auto ds = LoadDataset(std::string(VB_SHARED_DIR) + "/gapbench/practice/p01");
  if (!ds.ok()) GTEST_SKIP() << ds.status().message();
  model::PlantParams p = *model::Preset("taghizadeh2009");
  ASSERT_TRUE(model::AddEffect(&p.effects, "coil_heating", {{"R_th", 2.0}, {"C_th", 0.6}}).ok());
  EXPECT_LT(SessionRms(*ds, p), 2.3e-3);
  EXPECT_GT(SessionRms(*ds, *model::Preset("taghizadeh2009")), 40e-3);
}

// Regression: a run ending with current still flowing left the core's play state outside its band for the
// next run (which starts at rest), and the simulator looped forever on that surface.
TEST(ReplaySession, ResidualMagnetismStateCarriesWithoutStalling) {
  auto ds = LoadDataset(std::string(VB_SHARED_DIR) + "/gapbench/practice/p03");
  if (!ds.ok()) GTEST_SKIP() << ds.status().message();
  model::PlantParams p = *model::Preset("taghizadeh2009");
  ASSERT_TRUE(model::AddEffect(&p.effects, "residual_magnetism", {{"w", 0.0828}, {"alpha", 0.35}}).ok());
  EXPECT_LT(SessionRms(*ds, p), SessionRms(*ds, *model::Preset("taghizadeh2009")));
}

}  // namespace
}  // namespace vb::gap
