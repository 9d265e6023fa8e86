#include <gtest/gtest.h>

#include <cmath>

#include "experiment/metrics.h"

namespace vb::experiment {
namespace {

Trace Make(size_t n, double dt) {
  Trace t;
  t.sample_period_s = dt;
  t.Reserve(n);
  for (size_t k = 0; k < n; ++k) {
    t.t_s.push_back(k * dt);
    t.gate.push_back(k % 10 < 5 ? 1 : 0);
    t.v_coil_V.push_back(k % 10 < 5 ? 24.0 : -0.7);
    t.i_A.push_back(0.5 + (k % 2 ? 0.01 : -0.01));
    t.x_m.push_back(std::nan(""));
    t.v_mps.push_back(std::nan(""));
    t.ref.push_back(0.5);
    t.x_avg_m.push_back(std::nan(""));
    t.flow_kg_per_s.push_back(std::nan(""));
    t.v2_int_V2s.push_back(std::nan(""));  // no exact integrals: the sampled sums are used
    t.energy_int_J.push_back(std::nan(""));
    t.switch_count.push_back(std::nan(""));
  }
  return t;
}

TEST(Metrics, DefinitionsOnAKnownTrace) {
  const Trace t = Make(1000, 1e-4);
  const Metrics m = ComputeMetrics(t, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0);
  EXPECT_NEAR(m.rmse, 0.01, 1e-12);
  EXPECT_NEAR(m.iae, 0.01 * 1000 * 1e-4, 1e-12);
  EXPECT_NEAR(m.max_abs_error, 0.01, 1e-12);
  const double v2 = (24.0 * 24.0 + 0.7 * 0.7) / 2;
  EXPECT_NEAR(m.effort_rms, std::sqrt(v2), 1e-9);
  EXPECT_NEAR(m.effort_l2, std::sqrt(v2 * 1000 * 1e-4), 1e-9);
  EXPECT_NEAR(m.mean_current_A, 0.5, 1e-12);
  EXPECT_EQ(m.switches, 199);
  EXPECT_TRUE(std::isnan(m.opening_delay_s)) << "no position channel";
}

TEST(Metrics, WindowLimitsTheSamples) {
  const Trace t = Make(1000, 1e-4);
  const Metrics m = ComputeMetrics(t, ControlledVariable::kCurrent, 0.05, 0.0599, 0, 0);
  EXPECT_EQ(m.switches, 19);  // samples 500..599; the gate flips every 5 samples: at 505, 510, ..., 595
  const Metrics none = ComputeMetrics(t, ControlledVariable::kNone, 0.0, 1.0, 0, 0);
  EXPECT_TRUE(std::isnan(none.rmse));
}

}  // namespace
}  // namespace vb::experiment
