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


TEST(Metrics, AHoldHasNoOvershootOrSettlingAndAStepNoMaxErrorOfItsOwnStep) {
  // Hold: the window starts at the set-point (0.49 A against 0.5 A): overshoot and settling do not apply.
  Trace hold = Make(1000, 1e-4);
  const Metrics h = ComputeMetrics(hold, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0);
  EXPECT_TRUE(std::isnan(h.overshoot));
  EXPECT_TRUE(std::isnan(h.settling_time_s));
  EXPECT_NEAR(h.max_abs_error, 0.01, 1e-12);
  // Step: from 0 to 0.5 A with a 0.6 A peak; max |e| would only be the step itself.
  Trace step = Make(1000, 1e-4);
  for (size_t k = 0; k < 1000; ++k) step.i_A[k] = k < 100 ? 0.0 : k < 200 ? 0.6 : 0.5;
  const Metrics s = ComputeMetrics(step, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0);
  EXPECT_NEAR(s.overshoot, 0.2, 1e-12);
  EXPECT_NEAR(s.settling_time_s, 0.02, 1e-12);
  EXPECT_TRUE(std::isnan(s.max_abs_error));
}

TEST(Metrics, OpeningDelayOnlyFromAClosedValve) {
  Trace t = Make(1000, 1e-4);
  for (size_t k = 0; k < 1000; ++k) {
    t.gate[k] = k >= 100 ? 1 : 0;
    t.x_m[k] = k < 150 ? 0.0 : 1e-3;  // opens 5 ms after the rising edge
    t.flow_kg_per_s[k] = 0.0;
  }
  const Metrics closed = ComputeMetrics(t, ControlledVariable::kNone, 0.0, 1.0, 0.0, 1e-3);
  EXPECT_NEAR(closed.opening_delay_s, 5e-3, 1e-12);
  // The same rising edge while the valve is already open (a hold) opens nothing.
  for (size_t k = 0; k < 1000; ++k) t.x_m[k] = 1e-3;
  const Metrics open = ComputeMetrics(t, ControlledVariable::kNone, 0.0, 1.0, 0.0, 1e-3);
  EXPECT_TRUE(std::isnan(open.opening_delay_s));
  EXPECT_NEAR(open.mean_position_pct, 100.0, 1e-9);
}

TEST(Metrics, SwitchingRateAndDriverLossesFromTheDriverParameters) {
  // 20 kHz PWM sampled at 200 kHz (10 samples per period, 5 on): exact integrals as an emulator gives them.
  const double dt = 5e-6, vs = 24.0, vd = 0.7;
  Trace t = Make(2001, dt);
  double v2 = 0, e = 0, sw = 0;
  for (size_t k = 0; k < t.size(); ++k) {
    if (k > 0) {
      v2 += t.v_coil_V[k - 1] * t.v_coil_V[k - 1] * dt;
      e += t.v_coil_V[k - 1] * t.i_A[k - 1] * dt;
      sw += t.gate[k] != t.gate[k - 1];
    }
    t.v2_int_V2s[k] = v2;
    t.energy_int_J[k] = e;
    t.switch_count[k] = sw;
  }
  DriverLossInputs d;
  d.supply_V = vs;
  d.diode_drop_V = vd;
  d.low_side_flyback = true;
  const Metrics m = ComputeMetrics(t, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0, d);
  const double window = t.t_s.back();
  EXPECT_NEAR(m.switching_rate_Hz, m.switches / window, 1e-9);
  EXPECT_NEAR(m.switching_rate_Hz, 40000.0, 100.0);  // two edges per 50 us period
  // Q_off from the charge and energy balance; here the off-state charge is known sample by sample.
  double q_off = 0;
  for (size_t k = 0; k + 1 < t.size(); ++k) q_off += t.gate[k] == 0 ? t.i_A[k] * dt : 0.0;
  EXPECT_NEAR(m.diode_loss_W, vd * q_off / window, 2e-3);
  EXPECT_NEAR(m.switching_loss_W, 0.5 * (vs + vd) * m.mean_current_A * 100e-9 * m.switching_rate_Hz, 1e-12);
  EXPECT_NEAR(m.driver_loss_W, m.diode_loss_W + m.switching_loss_W, 1e-15);
  // Twice the edges, twice the switching loss; an H-bridge (another split) gets no loss estimate.
  d.switch_transition_s = 200e-9;
  EXPECT_NEAR(ComputeMetrics(t, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0, d).switching_loss_W,
              2 * m.switching_loss_W, 1e-12);
  d.low_side_flyback = false;
  EXPECT_TRUE(std::isnan(ComputeMetrics(t, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0, d).driver_loss_W));
  EXPECT_TRUE(std::isnan(ComputeMetrics(t, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0).driver_loss_W));
}

TEST(Metrics, RippleOfAnOpenLoopRunIsPeakToPeakAndMidRange) {
  Trace t = Make(1000, 1e-4);
  for (size_t k = 0; k < 1000; ++k) t.i_A[k] = 0.1 + 0.025 * std::sin(0.1 * k);
  const Metrics m = ComputeMetrics(t, ControlledVariable::kNone, 0.0, 1.0, 0, 0);
  EXPECT_NEAR(m.ripple_pp_A, 0.05, 1e-5);
  EXPECT_NEAR(m.ripple_mid_A, 0.1, 1e-5);
  EXPECT_TRUE(std::isnan(ComputeMetrics(t, ControlledVariable::kCurrent, 0.0, 1.0, 0, 0).ripple_pp_A))
      << "a closed-loop law's ripple is its tracking error";
}

}  // namespace
}  // namespace vb::experiment
