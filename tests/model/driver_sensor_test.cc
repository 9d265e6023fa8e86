// The driver's state machine and the current sensor alone (model/driver.h, model/sensor.h), as the simulator
// composes them (docs/model.md, "Structure").
#include <gtest/gtest.h>

#include <cmath>

#include "model/driver.h"
#include "model/sensor.h"

namespace vb::model {
namespace {

TEST(Driver, LowSideFlybackSuppliesFreewheelsThenBlocks) {
  Driver d(DriverParams{});
  EXPECT_TRUE(d.blocked());
  EXPECT_TRUE(d.Segment(24.0, 0.0, 0.0).blocked);
  ASSERT_TRUE(d.SetGate(1, 0.001));
  EXPECT_FALSE(d.SetGate(1, 0.002)) << "the same level is no change";
  DriveSegment on = d.Segment(24.0, 0.001, 0.0);
  EXPECT_FALSE(on.blocked);
  EXPECT_TRUE(on.from_supply);
  EXPECT_EQ(on.v0_V, 24.0);
  EXPECT_EQ(on.clamp, 0);
  ASSERT_TRUE(d.SetGate(0, 0.005));
  DriveSegment fw = d.Segment(24.0, 0.005, 1.2);
  EXPECT_EQ(fw.v0_V, -0.7);
  EXPECT_EQ(fw.clamp, +1) << "conduction ends when the current falls to 0";
  EXPECT_FALSE(fw.from_supply);
  d.OnCurrentZero();
  EXPECT_TRUE(d.Segment(24.0, 0.006, 0.0).blocked);
  // A current set from outside (the periodic steady-state search) makes the diode conduct again.
  d.Unblock();
  EXPECT_EQ(d.Segment(24.0, 0.006, 0.3).clamp, +1);
  // A freewheel with no current left blocks at once.
  EXPECT_TRUE(d.Segment(24.0, 0.006, 0.0).blocked);
  EXPECT_TRUE(d.blocked());
}

TEST(Driver, HBridgeDrivesBothWaysAndDecaysFast) {
  DriverParams p;
  p.kind = DriverKind::kHBridge;
  Driver d(p);
  d.SetGate(-1, 0.0);
  EXPECT_EQ(d.Segment(24.0, 0.0, 0.0).v0_V, -24.0);
  d.SetGate(0, 0.001);
  DriveSegment neg = d.Segment(24.0, 0.001, -0.5);
  EXPECT_DOUBLE_EQ(neg.v0_V, 24.0 + 1.4);
  EXPECT_EQ(neg.clamp, -1);
  DriveSegment pos = d.Segment(24.0, 0.001, 0.5);
  EXPECT_DOUBLE_EQ(pos.v0_V, -(24.0 + 1.4));
  EXPECT_EQ(pos.clamp, +1);
}

TEST(Driver, InternalElectronicsBoostsThenChopsThenReverses) {
  DriverParams p;
  p.kind = DriverKind::kInternalElectronics;
  p.boost_time_s = 5e-3;
  p.hold_current_A = 0.5;
  p.hold_band_A = 0.02;
  Driver d(p);
  d.SetGate(1, 0.010);
  DriveSegment boost = d.Segment(24.0, 0.010, 0.0);
  EXPECT_EQ(boost.v0_V, 24.0);
  EXPECT_DOUBLE_EQ(boost.t_end_s, 0.015);
  EXPECT_EQ(boost.level_dir, 0);
  // After the boost, above the band: the chopper starts off, freewheeling down to the lower level.
  DriveSegment off = d.Segment(24.0, 0.015, 1.5);
  EXPECT_EQ(off.v0_V, -0.7);
  EXPECT_EQ(off.level_dir, -1);
  EXPECT_DOUBLE_EQ(off.level_A, 0.49);
  d.OnLevelCrossed();
  DriveSegment on = d.Segment(24.0, 0.016, 0.49);
  EXPECT_EQ(on.v0_V, 24.0);
  EXPECT_EQ(on.level_dir, +1);
  EXPECT_DOUBLE_EQ(on.level_A, 0.51);
  // Release: the capacitor's reverse voltage decays from the falling edge.
  d.SetGate(0, 0.020);
  DriveSegment rev = d.Segment(24.0, 0.020, 0.5);
  EXPECT_EQ(rev.clamp, +1);
  EXPECT_DOUBLE_EQ(rev.VoltageAt(0.020), -24.0);
  EXPECT_NEAR(rev.VoltageAt(0.021), -24.0 * std::exp(-1.0), 1e-12);
}

TEST(Driver, PeekingChangesNothing) {
  DriverParams p;
  p.kind = DriverKind::kInternalElectronics;
  Driver d(p);
  d.SetGate(1, 0.0);
  // Peeking after the boost at a low current would start the chopper "on"; the state must not move.
  const DriveSegment peek = d.PeekSegment(24.0, 0.006, 0.1);
  EXPECT_EQ(peek.level_dir, +1);
  // The real call at a high current starts the chopper "off", as if nobody had peeked.
  EXPECT_EQ(d.Segment(24.0, 0.006, 1.0).level_dir, -1);
  Driver flyback(DriverParams{});
  flyback.Unblock();
  EXPECT_TRUE(flyback.PeekSegment(24.0, 0.0, 0.0).blocked);
  EXPECT_FALSE(flyback.blocked()) << "a peek does not block";
}

Effects SensorEffects(double tau_s, double delay_s, double gain = 1.0, double offset_A = 0.0) {
  Effects fx;
  fx.sensor_tau_s = tau_s;
  fx.sensor_delay_s = delay_s;
  fx.sensor_gain = gain;
  fx.sensor_offset_A = offset_A;
  return fx;
}

TEST(CurrentSensor, TheLagIsExactForACurrentLinearBetweenSamples) {
  const double tau = 5e-5, h = 1e-5, r = 1e3;  // a 1 A/ms ramp from 0
  CurrentSensor s(SensorEffects(tau, 0.0));
  s.SetSamplePeriod(h);
  EXPECT_FALSE(s.has_reading());
  for (int k = 0; k <= 50; ++k) {
    const double t = k * h;
    const double y = s.Sample(t, r * t);
    // tau y' = i - y, y(0) = 0:  y(t) = r (t - tau (1 - e^{-t/tau}))
    EXPECT_NEAR(y, r * (t - tau * (1.0 - std::exp(-t / tau))), 1e-13) << k;
  }
  EXPECT_TRUE(s.has_reading());
  EXPECT_NEAR(s.LastReading_A(), r * (50 * h - tau * (1.0 - std::exp(-50 * h / tau))), 1e-13);
  s.Reset();
  EXPECT_FALSE(s.has_reading());
  EXPECT_EQ(s.Sample(1.0, 0.25), 0.25) << "after Reset the lag starts at the first sample's current";
}

TEST(CurrentSensor, TheLatencyInterpolatesBetweenEarlierSamples) {
  const double h = 1e-5;
  CurrentSensor s(SensorEffects(0.0, 2.5 * h));
  s.SetSamplePeriod(h);
  for (int k = 0; k <= 20; ++k) {
    const double t = k * h, y = s.Sample(t, 3.0 + t * 1e3);
    if (k < 2) {
      EXPECT_EQ(y, 0.0) << "nothing read before the run: " << k;
    } else if (k == 2) {
      EXPECT_NEAR(y, 0.5 * 3.0, 1e-12) << "half of the first sample, half of 'before the run'";
    } else {
      EXPECT_NEAR(y, 3.0 + (t - 2.5 * h) * 1e3, 1e-12) << k;
    }
  }
}

TEST(CurrentSensor, TheStaticChainAppliesGainAndOffset) {
  CurrentSensor plain(SensorEffects(0.0, 0.0, 2.0, 0.1));
  EXPECT_FALSE(plain.dynamic());
  EXPECT_DOUBLE_EQ(plain.Sample(0.0, 1.5), 3.1);
  EXPECT_FALSE(plain.has_reading()) << "a sensor without memory has nothing to hold between samples";
  EXPECT_DOUBLE_EQ(plain.Static(-0.5), -0.9);
  CurrentSensor lagged(SensorEffects(1e-4, 0.0, 2.0, 0.1));
  EXPECT_DOUBLE_EQ(lagged.Sample(0.0, 1.5), 3.1);
  EXPECT_DOUBLE_EQ(lagged.LastReading_A(), 3.1);
}

}  // namespace
}  // namespace vb::model
