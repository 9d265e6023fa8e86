// Capabilities decide what runs: a spec that needs more than a bench offers is refused, naming the field.
// The HID capabilities come from the device emulator's IDENTITY answer, the U3's from U3Bench.
#include <gtest/gtest.h>

#include "experiment/capabilities.h"
#include "hw/hid/hid_bench.h"
#include "hw/testing/hid_device_emulator.h"
#include "hw/testing/u3_device_emulator.h"
#include "hw/u3/u3_bench.h"
#include "hw_test_util.h"

namespace vb::hw::testing {
namespace {

Capabilities HidCaps(const experiment::Experiment& e) {
  HidDeviceOptions dev;
  dev.valve = ValveFor(e);
  HidDeviceEmulator device(dev);
  auto b = HidBench::Open(device.Connect(), {});
  EXPECT_TRUE(b.ok());
  return (*b)->capabilities();
}

std::string CurrentControlJson(const std::string& controller, double supply_V = 24) {
  return R"({"bench":{"kind":"hid"},"conditions":{"supply_V":)" + std::to_string(supply_V) +
         R"(},"reference":{"constant":{"value":0.5}},"controller":{")" + controller +
         R"(":{}},"duration_s":0.05,"recording":{"rate_Hz":1000}})";
}

TEST(Capabilities, AFastLoopIsRefusedOnTheHidBenchWithTheOnDeviceAlternative) {
  const auto e = BuildOrDie(CurrentControlJson("pi_current"));
  const Capabilities hid = HidCaps(e);
  Status st = experiment::CheckCapabilities(e, hid);
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(st.message().find("faster than the bench's host loop of 1000 Hz"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("on-device: open_loop hysteresis pi"), std::string::npos) << st.message();
  // The same spec fits the emulated bench.
  EmulatedBench emu(ValveFor(e));
  EXPECT_TRUE(experiment::CheckCapabilities(e, emu.capabilities()).ok());
}

TEST(Capabilities, SupplyRecordingCarrierAndPositionAreChecked) {
  const auto open_loop = BuildOrDie(OpenLoopJson(0.05, 1000));
  Capabilities caps = HidCaps(open_loop);
  EXPECT_TRUE(experiment::CheckCapabilities(open_loop, caps).ok());
  caps.max_supply_V = 12;
  Status st = experiment::CheckCapabilities(open_loop, caps);
  EXPECT_NE(st.message().find("conditions.supply_V: 24 V exceeds the bench's 12 V"), std::string::npos)
      << st.message();
  caps = HidCaps(open_loop);
  const auto fast_rec = BuildOrDie(OpenLoopJson(0.05, 50'000));
  st = experiment::CheckCapabilities(fast_rec, caps);
  EXPECT_NE(st.message().find("recording.rate_Hz: 50000 Hz exceeds the bench's 20000 Hz"), std::string::npos)
      << st.message();
  const auto high_carrier = BuildOrDie(OpenLoopJson(0.05, 1000, 200e3));
  st = experiment::CheckCapabilities(high_carrier, caps);
  EXPECT_NE(st.message().find("controller.open_loop_pwm.segments[0].frequency_Hz: 200000 Hz is outside"),
            std::string::npos)
      << st.message();
  const auto position = BuildOrDie(
      R"({"bench":{"kind":"hid","model":{"preset":"lunge2013"}},"reference":{"constant":{"value":0.0001}},)"
      R"("controller":{"cascade_pi_position":{}},)"
      R"("duration_s":0.05,"recording":{"rate_Hz":1000}})");
  caps.max_control_rate_Hz = 1e9;
  st = experiment::CheckCapabilities(position, caps);
  EXPECT_NE(st.message().find("controls the position, and the bench does not measure it"), std::string::npos)
      << st.message();
}

}  // namespace
}  // namespace vb::hw::testing
