// Safety interlocks on any bench (the emulated one here, the HID one at the end), with faults injected by
// FaultyBench: every trip ends the run as failed with the reason, keeps the samples up to the trip, and leaves
// the bench below in its safe state (gate low, PWM stopped).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "hw/faulty_bench.h"
#include "hw/hid/hid_bench.h"
#include "hw/safety.h"
#include "hw/testing/hid_device_emulator.h"
#include "hw_test_util.h"

namespace vb::hw::testing {
namespace {

using Termination = experiment::RunSummary::Termination;

struct Tripped {
  Ran ran;
  bool inner_gate_low = false;
};

Tripped RunGuarded(const std::string& json, SafetyLimits limits, BenchFaults faults = {}) {
  const auto e = BuildOrDie(json);
  EmulatedBench emu(ValveFor(e));
  FaultyBench faulty(&emu, faults);
  SafetyBench safe(&faulty, limits);
  Tripped t;
  t.ran = RunOn(e, safe);
  t.inner_gate_low = emu.simulator().gate() == 0;
  EXPECT_GE(faulty.safe_state_calls(), 1);
  return t;
}

void ExpectTrip(const Tripped& t, const std::string& reason, size_t min_samples = 10) {
  EXPECT_EQ(t.ran.summary.termination, Termination::kFailed);
  EXPECT_NE(t.ran.summary.message.find("safety: " + reason), std::string::npos) << t.ran.summary.message;
  EXPECT_TRUE(t.inner_gate_low);
  EXPECT_GE(t.ran.trace.size(), min_samples);  // the samples up to the trip are kept
}

TEST(SafetyLimits, BadLimitsNameTheField) {
  SafetyLimits l;
  l.max_duty = 1.5;
  EXPECT_NE(l.Validate().message().find("safety.max_duty"), std::string::npos);
  l = SafetyLimits{};
  l.max_coil_temp_C = 80;
  EXPECT_NE(l.Validate().message().find("safety.coil_R_ohm"), std::string::npos);
}

TEST(Safety, CurrentLimitTripsAtTheSampleThatCrossedIt) {
  SafetyLimits l;
  l.max_current_A = 0.5;
  Tripped t = RunGuarded(OpenLoopJson(0.3, 10'000, 375, 0.9), l);
  ExpectTrip(t, "coil current");
  // Stopped within one check period (1 ms) of the crossing: the recorded current never got far past 0.5 A.
  const auto& i = t.ran.trace.i_A;
  size_t first = 0;
  while (first < i.size() && i[first] <= 0.5) ++first;
  ASSERT_LT(first, i.size());
  EXPECT_LE(t.ran.trace.t_s.back() - t.ran.trace.t_s[first], 1.1e-3);
  EXPECT_LT(*std::max_element(i.begin(), i.end()), 0.6);
}

TEST(Safety, DutyLimit) {
  SafetyLimits l;
  l.max_duty = 0.8;
  ExpectTrip(RunGuarded(OpenLoopJson(0.1, 1000, 375, 0.9), l), "duty 0.9 exceeds the limit of 0.8", 0);
  Tripped fine = RunGuarded(OpenLoopJson(0.1, 1000, 375, 0.7), l);
  EXPECT_TRUE(fine.ran.summary.ok()) << fine.ran.summary.message;
}

TEST(Safety, ContinuousOnTime) {
  SafetyLimits l;
  l.max_on_time_s = 0.05;
  // frequency 0, duty 1: the gate held high.
  Tripped t = RunGuarded(OpenLoopJson(0.3, 1000, 0, 1), l);
  ExpectTrip(t, "the gate was held high");
  EXPECT_NEAR(t.ran.trace.t_s.back(), 0.05, 2e-3);
  // PWM at duty 0.5 switches every period: never continuously on.
  EXPECT_TRUE(RunGuarded(OpenLoopJson(0.3, 1000, 375, 0.5), l).ran.summary.ok());
}

TEST(Safety, CoilTemperatureEstimate) {
  SafetyLimits l;
  l.max_coil_temp_C = 40;
  l.coil_R_ohm = 13;
  l.thermal_resistance_K_per_W = 20;
  l.thermal_time_constant_s = 0.2;
  const auto e = BuildOrDie(OpenLoopJson(1.0, 1000, 0, 1));
  EmulatedBench emu(ValveFor(e));
  SafetyBench safe(&emu, l);
  Ran r = RunOn(e, safe);
  EXPECT_EQ(r.summary.termination, Termination::kFailed);
  EXPECT_NE(r.summary.message.find("estimated coil temperature"), std::string::npos) << r.summary.message;
  EXPECT_GT(safe.coil_temp_C(), 40.0);
  EXPECT_LT(safe.coil_temp_C(), 45.0);  // found within one 1 ms check period
  EXPECT_EQ(emu.simulator().gate(), 0);
  // Heating at ~1.8 A * 1.8 A * 13 ohm ~ 42 W through 20 K/W: 15 K in roughly 0.2 s * 15/840: a few ms
  // after the current has risen; far sooner than the 1 s run.
  EXPECT_LT(r.trace.t_s.back(), 0.2);
}

TEST(Safety, DeviceErrorStaleAndNanMeasurementsTrip) {
  BenchFaults f;
  f.error_at_s = 0.05;
  ExpectTrip(RunGuarded(OpenLoopJson(0.2, 1000), {}, f), "bench error at t = 0.05 s: injected device error");
  f = BenchFaults{};
  f.stale_from_s = 0.05;
  ExpectTrip(RunGuarded(OpenLoopJson(0.2, 1000), {}, f), "stale measurement");
  f = BenchFaults{};
  f.nan_at_s = 0.05;
  ExpectTrip(RunGuarded(OpenLoopJson(0.2, 1000), {}, f), "the current measurement at t = 0.05 s is not a number");
  // A current sensor that reads 200 A high from 0.05 s: the samples trip the current limit (EmulatedBench: 100 A).
  f = BenchFaults{};
  f.current_offset_from_s = 0.05;
  f.current_offset_A = 200;
  ExpectTrip(RunGuarded(OpenLoopJson(0.2, 1000), {}, f), "coil current");
}

TEST(Safety, CancelLeavesTheBenchSafe) {
  const auto e = BuildOrDie(OpenLoopJson(0.2, 1000));
  EmulatedBench emu(ValveFor(e));
  FaultyBench faulty(&emu, {});
  SafetyBench safe(&faulty, {});
  std::atomic<bool> cancel{true};
  experiment::Trace trace;
  const auto s = experiment::Runner::Run(e, safe, &trace, &cancel);
  EXPECT_EQ(s.termination, Termination::kCancelled);
  EXPECT_GE(faulty.safe_state_calls(), 1);
  EXPECT_EQ(emu.simulator().gate(), 0);
}

TEST(Safety, SoftwareWatchdogCatchesAHungLoop) {
  const auto e = BuildOrDie(OpenLoopJson(1.0, 1000));
  EmulatedBench emu(ValveFor(e));
  SafetyLimits l;
  l.watchdog_s = 0.03;
  SafetyBench safe(&emu, l);
  ASSERT_TRUE(safe.Configure(e.run).ok());
  ASSERT_TRUE(safe.Start(nullptr).ok());
  ASSERT_TRUE(safe.Apply(SwitchCommand::Gate(1)).ok());
  Measurement m;
  ASSERT_TRUE(safe.AdvanceTo(0.01, &m).ok());
  EXPECT_EQ(emu.simulator().gate(), 1);
  // The loop hangs (a controller stuck outside the bench): the watchdog thread acts within ~1.25 watchdog_s.
  const auto t0 = std::chrono::steady_clock::now();
  while (!safe.tripped() && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(5))
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(safe.tripped());
  EXPECT_EQ(emu.simulator().gate(), 0);
  Status st = safe.AdvanceTo(0.02, &m);
  EXPECT_EQ(st.code(), StatusCode::kAborted);
  EXPECT_NE(st.message().find("software watchdog"), std::string::npos) << st.message();
  (void)safe.Stop();
}

TEST(Safety, WatchdogStaysQuietWhileTheLoopRuns) {
  SafetyLimits l;
  l.watchdog_s = 0.5;
  Tripped t = RunGuarded(OpenLoopJson(0.5, 10'000), l);
  EXPECT_TRUE(t.ran.summary.ok()) << t.ran.summary.message;
}

TEST(Safety, InterlocksWorkOnTheHidBenchToo) {
  const auto e = BuildOrDie(OpenLoopJson(0.3, 1000, 375, 0.9));
  HidDeviceOptions dev_opt;
  dev_opt.valve = ValveFor(e);
  HidDeviceEmulator device(dev_opt);
  auto hid = HidBench::Open(device.Connect(), {});
  ASSERT_TRUE(hid.ok()) << hid.status().message();
  SafetyLimits l;
  l.max_current_A = 0.5;  // below the device's own 3 A trip: the host interlock acts first
  SafetyBench safe(hid->get(), l);
  Ran r = RunOn(e, safe);
  EXPECT_EQ(r.summary.termination, Termination::kFailed);
  EXPECT_NE(r.summary.message.find("safety: coil current"), std::string::npos) << r.summary.message;
  EXPECT_EQ(device.gate(), 0);
  EXPECT_FALSE(device.pwm_running());
  EXPECT_TRUE(device.faults().empty());
}

}  // namespace
}  // namespace vb::hw::testing
