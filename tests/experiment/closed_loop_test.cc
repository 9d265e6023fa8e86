// Every current law regulates the emulated taghizadeh2009 valve (the full nonlinear model, spool moving,
// flyback driver) on the comparison task of examples/compare-current-controllers.json.
#include <gtest/gtest.h>

#include <cmath>

#include "experiment/runner.h"
#include "hw/emulated_bench.h"

namespace vb::experiment {
namespace {

struct LawCase {
  const char* variant;
  double rmse_max_A;      // over the hold, 20-100 ms
  double mean_err_max_A;  // |mean(i) - 0.5 A|
};

class CurrentLawOnEmulator : public ::testing::TestWithParam<LawCase> {};

TEST_P(CurrentLawOnEmulator, HoldsTheReferenceAfterOpeningTheValve) {
  const LawCase c = GetParam();
  auto spec = LoadSpecFile(std::string(VB_SOURCE_DIR) + "/examples/compare-current-controllers.json");
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  auto runs = ExpandSweep(*spec);
  ASSERT_TRUE(runs.ok());
  const ExperimentSpec* mine = nullptr;
  for (const auto& r : *runs)
    if (r.name() == std::string("compare-current-controllers/") + c.variant) mine = &r;
  ASSERT_NE(mine, nullptr) << c.variant;
  auto e = BuildExperiment(*mine);
  ASSERT_TRUE(e.ok()) << e.status().message();
  hw::EmulatedBenchOptions opts;
  opts.plant = e->plant;
  opts.driver = e->driver;
  hw::EmulatedBench bench(opts);
  Trace trace;
  RunSummary s = Runner::Run(*e, bench, &trace);
  ASSERT_TRUE(s.ok()) << s.message;
  EXPECT_LT(s.metrics.rmse, c.rmse_max_A);
  EXPECT_LT(std::abs(s.metrics.mean_current_A - 0.5), c.mean_err_max_A);
  // The switching pulse opened the valve, and it stays open at the holding current.
  const Metrics whole = ComputeMetrics(trace, ControlledVariable::kCurrent, 0.0, 0.1, e->plant.x_min_m,
                                       e->plant.x_max_m);
  EXPECT_NEAR(whole.opening_delay_s, 4.06e-3, 0.3e-3);
  EXPECT_NEAR(trace.x_m.back(), e->plant.x_max_m, 1e-12);
}

INSTANTIATE_TEST_SUITE_P(Seed001, CurrentLawOnEmulator,
                         ::testing::Values(LawCase{"hysteresis", 7e-3, 2e-3}, LawCase{"pi", 2e-3, 2e-3},
                                           LawCase{"predictive", 2e-3, 2e-3}, LawCase{"fuzzy", 2e-3, 2e-3}),
                         [](const auto& info) { return std::string(info.param.variant); });

// A law that does not regulate must fail the bound: open-loop full-on gives ~1.8 A, not 0.5 A.
TEST(CurrentLawOnEmulator, TheBoundDiscriminates) {
  auto spec = LoadSpecFile(std::string(VB_SOURCE_DIR) + "/examples/compare-current-controllers.json");
  ASSERT_TRUE(spec.ok());
  spec->clear_variants();
  spec->mutable_controller()->mutable_open_loop_pwm()->add_segments()->set_duty(1.0);
  auto e = BuildExperiment(*spec);
  ASSERT_TRUE(e.ok()) << e.status().message();
  hw::EmulatedBenchOptions opts;
  opts.plant = e->plant;
  hw::EmulatedBench bench(opts);
  Trace trace;
  RunSummary s = Runner::Run(*e, bench, &trace);
  ASSERT_TRUE(s.ok());
  EXPECT_GT(std::abs(s.metrics.mean_current_A - 0.5), 0.5);
}

}  // namespace
}  // namespace vb::experiment
