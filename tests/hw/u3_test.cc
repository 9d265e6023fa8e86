// The LabJack U3 bench: the codec against bytes published with LabJack's own driver, the timer arithmetic,
// and U3Bench's real protocol code driven against the U3 device emulator with faults injected on the wire.
#include <gtest/gtest.h>

#include <cstdio>

#include <cmath>

#include "hw/testing/faulty_transport.h"
#include "hw/testing/u3_device_emulator.h"
#include "hw/u3/u3_bench.h"
#include "hw/u3/u3_protocol.h"
#include "hw_test_util.h"

namespace vb::hw::testing {
namespace {

TEST(U3Protocol, FeedbackBitStateWriteMatchesTheGuideExample) {
  // LabJack's docstring example: BitStateWrite(IONumber = 5, State = 0) is sent as
  // [0x0b, 0xf8, 0x02, 0x00, 0x10, 0x00, 0x00, 0x0b, 0x05, 0x00] and answered
  // [0xfa, 0xf8, 0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00].
  u3::FeedbackBuilder fb;
  fb.BitStateWrite(5, false);
  const u3::Packet p = fb.Finish();
  const std::uint8_t want[] = {0x0b, 0xf8, 0x02, 0x00, 0x10, 0x00, 0x00, 0x0b, 0x05, 0x00};
  ASSERT_EQ(p.size(), sizeof(want));
  for (size_t k = 0; k < sizeof(want); ++k) EXPECT_EQ(p[k], want[k]) << "byte " << k;
  EXPECT_EQ(fb.ResponseSize(), 10u);
  const std::uint8_t reply[] = {0xfa, 0xf8, 0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00};
  EXPECT_TRUE(u3::CheckFeedbackResponse(reply, sizeof(reply), 10).ok());
  const u3::Packet ours = u3::EncodeFeedbackResponse(0, 0, nullptr, 0);
  for (size_t k = 0; k < sizeof(reply); ++k) EXPECT_EQ(ours[k], reply[k]) << "byte " << k;
}

TEST(U3Protocol, ADeviceErrorcodeIsARefusalNotAnInternalError) {
  // A normal response [Checksum8, response byte, errorcode, 0] with errorcode 1 (SCRATCH_WRT_FAIL).
  std::uint8_t d[4] = {0, 0xA9, 1, 0};
  d[0] = u3::Checksum8(d, sizeof d);
  const Status st = u3::CheckNormal(d, sizeof d, 0xA9);
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition) << st.ToString();
  EXPECT_NE(st.message().find("device errorcode"), std::string::npos) << st.message();
}

TEST(U3Protocol, ChecksumsAndFraming) {
  // Checksum8 folds the carry twice: 0xF8 + 0x02 + 0x10 = 0x10A -> 0x0A + 0x01 = 0x0B.
  const std::uint8_t head[] = {0x00, 0xF8, 0x02, 0x00, 0x10, 0x00};
  EXPECT_EQ(u3::Checksum8(head, 6), 0x0B);
  EXPECT_EQ(u3::NormalCommand(u3::kStreamStart)[0], 0xA8);  // StreamStart is 0xA8 0xA8
  u3::Packet p = u3::Encode(u3::ConfigIO{1, 4, 0x01});
  EXPECT_EQ(p.size(), 12u);
  EXPECT_EQ(p[3], 0x0B);
  EXPECT_EQ(p[8], 0x41);  // one timer, pin offset 4
  u3::Packet resp = u3::EncodeConfigIOResponse(u3::ConfigIO{1, 4, 0x01}, 0);
  u3::ConfigIO back;
  ASSERT_TRUE(u3::DecodeConfigIO(resp.data(), resp.size(), &back).ok());
  resp[9] ^= 1;  // a payload bit: Checksum16 catches it
  Status st = u3::DecodeConfigIO(resp.data(), resp.size(), &back);
  EXPECT_EQ(st.code(), StatusCode::kDataLoss);
  EXPECT_NE(st.message().find("bad Checksum16"), std::string::npos) << st.message();
  resp[9] ^= 1;
  resp[4] ^= 1;  // the checksum itself
  EXPECT_FALSE(u3::DecodeConfigIO(resp.data(), resp.size(), &back).ok());
  st = u3::DecodeConfigIO(resp.data(), 7, &back);
  EXPECT_NE(st.message().find("short packet: 7 of 12"), std::string::npos) << st.message();
  u3::StreamData d;
  d.count = 4;
  d.packet_number = 255;
  d.samples = {1, 2, 0xFFFF, 4};
  const u3::Packet sd = u3::Encode(d);
  EXPECT_EQ(sd.size(), 22u);
  EXPECT_EQ(sd[1], 0xF9);
  EXPECT_EQ(sd[3], 0xC0);
  u3::StreamData dd;
  ASSERT_TRUE(u3::DecodeStreamData(sd.data(), sd.size(), 4, &dd).ok());
  EXPECT_EQ(dd.packet_number, 255);
  EXPECT_EQ(dd.samples[2], 0xFFFF);
}

TEST(U3Timer, RealisesCarriersExactlyOrNamesTheNearest) {
  auto pwm = RealiseU3Pwm(375.0);  // 12 MHz / 125, 8-bit
  ASSERT_TRUE(pwm.ok()) << pwm.status().message();
  EXPECT_EQ(pwm->mode, u3::kTimerModePwm8);
  EXPECT_DOUBLE_EQ(u3::TimerClockHz(pwm->clock) / 256.0, 375.0);
  pwm = RealiseU3Pwm(732.421875);  // 48 MHz / 65536: 16-bit preferred
  ASSERT_TRUE(pwm.ok());
  EXPECT_EQ(pwm->mode, u3::kTimerModePwm16);
  pwm = RealiseU3Pwm(1000.0);
  ASSERT_FALSE(pwm.ok());
  EXPECT_NE(pwm.status().message().find("nearest"), std::string::npos) << pwm.status().message();
  EXPECT_EQ(U3TimerValue(u3::kTimerModePwm8, 0.5), 0x8000);
  EXPECT_DOUBLE_EQ(U3Duty(u3::kTimerModePwm8, U3TimerValue(u3::kTimerModePwm8, 0.5)), 0.5);
  EXPECT_DOUBLE_EQ(U3Duty(u3::kTimerModePwm16, U3TimerValue(u3::kTimerModePwm16, 0.25)), 0.25);
}

struct U3Rig {
  explicit U3Rig(const experiment::Experiment& e, TransportFaults faults = {}, U3BenchOptions opt = {}) {
    U3DeviceOptions dev;
    dev.valve = ValveFor(e);
    device = std::make_unique<U3DeviceEmulator>(dev);
    auto t = std::make_unique<FaultyTransport>(device->Connect(), faults, [this] { device->Unplug(); });
    wire = t.get();
    auto b = U3Bench::Open(std::move(t), opt);
    EXPECT_TRUE(b.ok()) << b.status().message();
    bench = std::move(b.value());
  }
  std::unique_ptr<U3DeviceEmulator> device;
  FaultyTransport* wire = nullptr;
  std::unique_ptr<U3Bench> bench;
};

void ExpectSafe(const U3DeviceEmulator& d) {
  EXPECT_EQ(d.gate(), 0);
  EXPECT_FALSE(d.timer_running());
}

TEST(U3Bench, IdentifiesTheDevice) {
  const auto e = BuildOrDie(OpenLoopJson(0.05, 1000));
  U3Rig rig(e);
  EXPECT_EQ(rig.bench->capabilities().kind, "u3");
  EXPECT_EQ(rig.bench->capabilities().serial, "320012345");
  EXPECT_EQ(rig.bench->info().version_info, 2);
  U3BenchOptions other;
  other.serial = 42;
  U3DeviceOptions dev;
  dev.valve = ValveFor(e);
  U3DeviceEmulator device(dev);
  auto b = U3Bench::Open(device.Connect(), other);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("serial 320012345, configured 42"), std::string::npos)
      << b.status().message();
}

TEST(U3Bench, SpecRunsUnchangedAndMatchesTheEmulatedBench) {
  // 0.3 s at 1 kHz: 300 stream packets, the 8-bit packet counter wraps once.
  const auto e = BuildOrDie(OpenLoopJson(0.3, 1000));
  U3Rig rig(e);
  Ran u3r = RunOn(e, *rig.bench);
  ASSERT_TRUE(u3r.summary.ok()) << u3r.summary.message;
  EmulatedBench emu(ValveFor(e));
  Ran ref = RunOn(e, emu);
  ASSERT_TRUE(ref.summary.ok());
  ASSERT_EQ(u3r.trace.size(), ref.trace.size());
  const double carrier_Hz = 375.0, duty = 0.5;
  auto at_edge = [&](double t) {
    const double phase = t * carrier_Hz - std::floor(t * carrier_Hz + 1e-9);
    return std::abs(phase) < 1e-6 || std::abs(phase - duty) < 1e-6;
  };
  double max_err = 0.0, mean = 0.0;
  size_t compared = 0;
  for (size_t k = 0; k < ref.trace.size(); ++k) {
    ASSERT_NEAR(u3r.trace.t_s[k], ref.trace.t_s[k], 1e-12);
    if (!at_edge(ref.trace.t_s[k])) {
      EXPECT_EQ(u3r.trace.gate[k], ref.trace.gate[k]) << "t = " << ref.trace.t_s[k];
      ++compared;
    }
    max_err = std::max(max_err, std::abs(u3r.trace.i_A[k] - ref.trace.i_A[k]));
    mean += ref.trace.i_A[k] / ref.trace.size();
  }
  EXPECT_GT(compared, ref.trace.size() * 7 / 10);
  EXPECT_GT(mean, 0.3);
  std::printf("U3 vs emulated bench: max |di| %.1f uA over %zu samples (bound 18.6 uA)\n", max_err * 1e6,
              ref.trace.size());
  // Half an AIN count (2.44 V / 65536 at 1 A/V: 18.6 uA); 375 Hz and duty 0.5 are exact on the U3's timer.
  EXPECT_LE(max_err, 0.5 * u3::kNominalAinSlope_V + 1e-9);
  ExpectSafe(*rig.device);
  EXPECT_FALSE(rig.device->streaming());
}

struct U3FaultCase {
  const char* name;
  TransportFaults faults;
  const char* reason;
};

class U3Fault : public ::testing::TestWithParam<U3FaultCase> {};

TEST_P(U3Fault, FailsWithTheReasonKeepsTheSamplesAndIsSafe) {
  const auto e = BuildOrDie(OpenLoopJson(0.2, 1000));
  U3Rig rig(e, GetParam().faults);
  Ran r = RunOn(e, *rig.bench);
  EXPECT_EQ(r.summary.termination, experiment::RunSummary::Termination::kFailed);
  EXPECT_NE(r.summary.message.find(GetParam().reason), std::string::npos) << r.summary.message;
  EXPECT_GT(r.trace.size(), 20u);
  EXPECT_LT(r.trace.size(), 150u);
  ExpectSafe(*rig.device);
}

TransportFaults OnStream(long read, long TransportFaults::*field) {
  TransportFaults f;
  f.endpoint = u3::kEpStreamIn;
  f.*field = read;
  f.corrupt_byte = 12;   // the first sample's LSB
  f.checksum_byte = 4;   // Checksum16 LSB
  f.short_bytes = 10;
  return f;
}

INSTANTIATE_TEST_SUITE_P(
    Wire, U3Fault,
    ::testing::Values(
        U3FaultCase{"timeout", OnStream(60, &TransportFaults::timeout_from_read), "no answer within"},
        U3FaultCase{"short", OnStream(60, &TransportFaults::short_read_at), "short packet: 10 of 18"},
        U3FaultCase{"corrupt", OnStream(60, &TransportFaults::corrupt_read_at), "bad Checksum16"},
        U3FaultCase{"checksum", OnStream(60, &TransportFaults::bad_checksum_at), "bad Checksum16"},
        U3FaultCase{"stale", OnStream(60, &TransportFaults::stale_read_at), "stale stream packet"},
        U3FaultCase{"unplug", OnStream(60, &TransportFaults::unplug_at_read), "device disconnected"}),
    [](const auto& info) { return std::string(info.param.name); });

TEST(U3Bench, ACommandWithABadChecksumIsNoticed) {
  // Corrupt the host's own command on the way out: the U3 answers 0xB8 0xB8 and the run fails.
  const auto e = BuildOrDie(OpenLoopJson(0.1, 1000));
  U3Rig rig(e);
  ASSERT_TRUE(rig.bench->Configure(e.run).ok());
  ASSERT_TRUE(rig.bench->Start(nullptr).ok());
  auto side = rig.device->Connect();
  u3::FeedbackBuilder fb;
  fb.BitStateWrite(4, true);
  u3::Packet p = fb.Finish();
  p[4] ^= 0xFF;
  ASSERT_EQ(side->Write(u3::kEpCommandOut, p.data(), p.size(), 0), IoStatus::kOk);
  // The rejected command was not executed, and its reply is waiting where the bench's next answer should be.
  EXPECT_EQ(rig.device->gate(), 0);
  EXPECT_EQ(rig.device->bad_checksums(), 1);
  Status st = rig.bench->Apply(SwitchCommand::Pwm(0.5, 375));
  EXPECT_EQ(st.code(), StatusCode::kDataLoss);
  EXPECT_NE(st.message().find("rejected the command's checksum"), std::string::npos) << st.message();
}

TEST(U3Bench, HungHostIsCaughtByTheDeviceWatchdog) {
  const auto e = BuildOrDie(OpenLoopJson(3.0, 1000));
  U3Rig rig(e);
  ASSERT_TRUE(rig.bench->Configure(e.run).ok());
  ASSERT_TRUE(rig.bench->Start(nullptr).ok());
  ASSERT_TRUE(rig.bench->Apply(SwitchCommand::Pwm(0.5, 375)).ok());
  Measurement m;
  ASSERT_TRUE(rig.bench->AdvanceTo(0.01, &m).ok());
  EXPECT_TRUE(rig.device->timer_running());
  rig.device->RunFor(0.5);  // within the 1 s watchdog: still driving
  EXPECT_TRUE(rig.device->timer_running());
  EXPECT_EQ(rig.device->resets(), 0);
  rig.device->RunFor(1.0);  // past it: the U3 resets itself
  ExpectSafe(*rig.device);
  EXPECT_EQ(rig.device->resets(), 1);
}

TEST(U3Bench, HeartbeatsKeepTheWatchdogQuietOnALongRun) {
  const auto e = BuildOrDie(OpenLoopJson(2.5, 1000));  // open loop: no command after t = 0
  U3Rig rig(e);
  Ran r = RunOn(e, *rig.bench);
  EXPECT_TRUE(r.summary.ok()) << r.summary.message;
  EXPECT_EQ(rig.device->resets(), 0);
}

TEST(U3Bench, ReconnectsAfterAnUnplug) {
  const auto e = BuildOrDie(OpenLoopJson(0.1, 1000));
  U3Rig rig(e, OnStream(30, &TransportFaults::unplug_at_read));
  Ran first = RunOn(e, *rig.bench);
  EXPECT_FALSE(first.summary.ok());
  rig.device->Replug();
  Ran second = RunOn(e, *rig.bench);
  EXPECT_TRUE(second.summary.ok()) << second.summary.message;
  EXPECT_EQ(second.trace.size(), 101u);
}

TEST(U3Bench, RefusesWhatTheDeviceCannotDo) {
  const auto e = BuildOrDie(OpenLoopJson(0.1, 1000));
  U3Rig rig(e);
  RunConfig rc = e.run;
  rc.sample_rate_Hz = 7000;  // 4 MHz / 571.4, 48 MHz / 6857.1: not a whole ScanInterval
  Status st = rig.bench->Configure(rc);
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(st.message().find("ScanInterval"), std::string::npos) << st.message();
  rc.sample_rate_Hz = 1000;
  rc.supply_V = 30;
  EXPECT_NE(rig.bench->Configure(rc).message().find("supply_V"), std::string::npos);
  rc.supply_V = 24;
  ASSERT_TRUE(rig.bench->Configure(rc).ok());
  ASSERT_TRUE(rig.bench->Start(nullptr).ok());
  EXPECT_EQ(rig.bench->Apply(SwitchCommand::Gate(-1)).code(), StatusCode::kFailedPrecondition);
  st = rig.bench->Apply(SwitchCommand::Pwm(0.5, 1000));
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(st.message().find("cannot make 1000 Hz exactly"), std::string::npos) << st.message();
  // Gate-level commands drive the pin digitally.
  ASSERT_TRUE(rig.bench->Apply(SwitchCommand::Gate(1)).ok());
  EXPECT_EQ(rig.device->gate(), 1);
  EXPECT_FALSE(rig.device->timer_running());
  rig.bench->SafeState();
  EXPECT_EQ(rig.device->gate(), 0);
}

}  // namespace
}  // namespace vb::hw::testing
