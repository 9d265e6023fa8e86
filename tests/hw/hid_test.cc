// The HID bench: the protocol codec (golden bytes, CRC), and HidBench's real protocol code driven against the
// device emulator (hw/testing), with faults injected on the wire. Every fault must end the run as failed with
// the reason, keep the samples up to the fault, and leave the device's gate low with its PWM stopped.
#include <gtest/gtest.h>

#include <cstdio>

#include <cmath>
#include <cstring>

#include "hw/hid/hid_bench.h"
#include "hw/hid/hid_protocol.h"
#include "hw/testing/faulty_transport.h"
#include "hw/testing/hid_device_emulator.h"
#include "hw_test_util.h"

namespace vb::hw::testing {
namespace {

TEST(HidProtocol, Crc8IsTheAtmVariant) {
  const char* check = "123456789";  // the catalogue check value of CRC-8 (poly 0x07, init 0): 0xF4
  EXPECT_EQ(hid::Crc8(reinterpret_cast<const std::uint8_t*>(check), 9), 0xF4);
}

TEST(HidProtocol, SetPwmGoldenBytes) {
  hid::SetPwm p;
  p.carrier_Hz = 1000.0f;
  p.duty = 0x8000;
  p.restart_carrier = true;
  const hid::Report r = hid::Encode(p, 7);
  const std::uint8_t head[] = {0x05, 0x01, 0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x7A, 0x44, 0x00, 0x80, 0x01};
  for (size_t k = 0; k < sizeof(head); ++k) EXPECT_EQ(r[k], head[k]) << "byte " << k;
  for (size_t k = sizeof(head); k < 63; ++k) EXPECT_EQ(r[k], 0) << "byte " << k;
  EXPECT_EQ(r[63], hid::Crc8(r.data(), 63));
}

TEST(HidProtocol, SamplesRoundTripAndLayout) {
  hid::Samples s;
  s.first_index = 0x01020304;
  s.count = 3;
  s.gate_bits = 0b101;
  s.last_host_seq = 9;
  s.current[0] = -2;
  s.current[2] = 1000;
  const hid::Report r = hid::Encode(s, 0xFFFFFFFFu);
  EXPECT_EQ(r[0], 0x83);
  EXPECT_EQ(r[6], 0x04);
  EXPECT_EQ(r[9], 0x01);
  EXPECT_EQ(r[10], 3);
  EXPECT_EQ(r[20], 0xFE);  // -2 as int16 LE
  EXPECT_EQ(r[21], 0xFF);
  EXPECT_EQ(r[24], 0xE8);  // 1000 = 0x03E8
  hid::Header h;
  ASSERT_TRUE(hid::ParseHeader(r.data(), r.size(), &h).ok());
  EXPECT_EQ(h.seq, 0xFFFFFFFFu);
  hid::Samples back;
  ASSERT_TRUE(hid::Decode(r, &back).ok());
  EXPECT_EQ(back.first_index, s.first_index);
  EXPECT_EQ(back.current[0], -2);
  EXPECT_EQ(back.current[2], 1000);
  EXPECT_EQ(back.gate_bits, 0b101u);
}

TEST(HidProtocol, EverySingleBitFlipIsDetected) {
  const hid::Report good = hid::Encode(hid::SetGate{1}, 42);
  hid::Header h;
  for (size_t byte = 0; byte < hid::kReportSize; ++byte)
    for (int bit = 0; bit < 8; ++bit) {
      hid::Report bad = good;
      bad[byte] ^= static_cast<std::uint8_t>(1 << bit);
      EXPECT_FALSE(hid::ParseHeader(bad.data(), bad.size(), &h).ok()) << byte << ":" << bit;
    }
}

TEST(HidProtocol, BadInputNamesTheProblem) {
  hid::Header h;
  const hid::Report r = hid::Encode(hid::Type::kHeartbeat, 1);
  Status st = hid::ParseHeader(r.data(), 17, &h);
  EXPECT_EQ(st.code(), StatusCode::kDataLoss);
  EXPECT_NE(st.message().find("short report: 17 of 64 bytes"), std::string::npos) << st.message();
  hid::Samples s;
  s.count = 21;
  hid::Samples back;
  st = hid::Decode(hid::Encode(s, 1), &back);
  EXPECT_NE(st.message().find("samples.count"), std::string::npos) << st.message();
  hid::Configure c;
  c.sample_rate_Hz = 1000;
  c.samples_per_report = 1;
  c.watchdog_ms = 0;
  st = hid::Decode(hid::Encode(c, 1), &c);
  EXPECT_NE(st.message().find("configure.watchdog_ms"), std::string::npos) << st.message();
}

// A device with the spec's valve behind it, and a HidBench on it through an optional fault injector.
struct Rig {
  explicit Rig(const experiment::Experiment& e, TransportFaults faults = {}, HidBenchOptions opt = {},
               HidDeviceOptions dev_opt = {}) {
    dev_opt.valve = ValveFor(e);
    device = std::make_unique<HidDeviceEmulator>(dev_opt);
    auto t = std::make_unique<FaultyTransport>(device->Connect(), faults, [this] { device->Unplug(); });
    wire = t.get();
    auto b = HidBench::Open(std::move(t), opt);
    EXPECT_TRUE(b.ok()) << b.status().message();
    bench = std::move(b.value());
  }
  std::unique_ptr<HidDeviceEmulator> device;
  FaultyTransport* wire = nullptr;
  std::unique_ptr<HidBench> bench;
};

void ExpectSafe(const HidDeviceEmulator& d) {
  EXPECT_EQ(d.gate(), 0);
  EXPECT_FALSE(d.pwm_running());
}

TEST(HidBench, CapabilitiesComeFromTheDevice) {
  const auto e = BuildOrDie(OpenLoopJson(0.05, 1000));
  Rig rig(e);
  const Capabilities& c = rig.bench->capabilities();
  EXPECT_EQ(c.kind, "hid");
  EXPECT_EQ(c.serial, "EMU-HID-0001");
  EXPECT_DOUBLE_EQ(c.max_supply_V, 48.0);
  EXPECT_DOUBLE_EQ(c.max_control_rate_Hz, 1000.0);
  EXPECT_DOUBLE_EQ(c.max_sample_rate_Hz, 20000.0);
  EXPECT_DOUBLE_EQ(c.max_current_A, 3.0);
  EXPECT_EQ(c.device_loops, (std::vector<std::string>{"open_loop", "hysteresis", "pi"}));
}

TEST(HidBench, SpecRunsUnchangedAndMatchesTheEmulatedBench) {
  // 0.2 s at 1 kHz: 200 reports, crossing the device's u32 sequence wrap (it starts at 0xFFFFFFF0).
  const auto e = BuildOrDie(OpenLoopJson(0.2, 1000));
  Rig rig(e);
  Ran hid = RunOn(e, *rig.bench);
  ASSERT_TRUE(hid.summary.ok()) << hid.summary.message;
  EmulatedBench emu(ValveFor(e));
  Ran ref = RunOn(e, emu);
  ASSERT_TRUE(ref.summary.ok());
  ASSERT_EQ(hid.trace.size(), ref.trace.size());
  // A sample taken at the very instant of a gate edge may show either level (the emulated bench shows the
  // level after the edge, a device sampling at the edge the one before): the gate is compared everywhere else.
  const double carrier_Hz = 375.0, duty = 0.5;
  auto at_edge = [&](double t) {
    const double phase = t * carrier_Hz - std::floor(t * carrier_Hz + 1e-9);
    return std::abs(phase) < 1e-6 || std::abs(phase - duty) < 1e-6;
  };
  double max_err = 0.0, mean = 0.0;
  size_t compared = 0;
  for (size_t k = 0; k < ref.trace.size(); ++k) {
    ASSERT_NEAR(hid.trace.t_s[k], ref.trace.t_s[k], 1e-12);
    if (!at_edge(ref.trace.t_s[k])) {
      EXPECT_EQ(hid.trace.gate[k], ref.trace.gate[k]) << "t = " << ref.trace.t_s[k];
      ++compared;
    }
    max_err = std::max(max_err, std::abs(hid.trace.i_A[k] - ref.trace.i_A[k]));
    mean += ref.trace.i_A[k] / ref.trace.size();
  }
  EXPECT_GT(compared, ref.trace.size() * 7 / 10);  // 1 in 4 samples of this carrier falls on an edge
  EXPECT_GT(mean, 0.3);          // the valve really was driven
  std::printf("HID vs emulated bench: max |di| %.1f uA over %zu samples (bound 65 uA)\n", max_err * 1e6,
              ref.trace.size());
  // Half a count (0.1 mA) of quantisation, plus the protocol's 16-bit duty (0.5 goes out as 32768/65535): at
  // most 0.5/65535 of the 1.85 A full-on current (24 V / 13 ohm), 14 uA. Nothing else.
  EXPECT_LE(max_err, 0.5e-4 + 1.5e-5);
  ExpectSafe(*rig.device);
  EXPECT_FALSE(rig.device->sampling());
}

struct FaultCase {
  const char* name;
  TransportFaults faults;
  const char* reason;
};

class HidFault : public ::testing::TestWithParam<FaultCase> {};

TEST_P(HidFault, FailsWithTheReasonKeepsTheSamplesAndIsSafe) {
  const auto e = BuildOrDie(OpenLoopJson(0.2, 1000));
  Rig rig(e, GetParam().faults);
  Ran r = RunOn(e, *rig.bench);
  EXPECT_EQ(r.summary.termination, experiment::RunSummary::Termination::kFailed);
  EXPECT_NE(r.summary.message.find(GetParam().reason), std::string::npos) << r.summary.message;
  EXPECT_GT(r.trace.size(), 20u);   // the samples up to the fault are kept
  EXPECT_LT(r.trace.size(), 150u);
  ExpectSafe(*rig.device);
}

TransportFaults At(long read, long TransportFaults::*field) {
  TransportFaults f;
  f.*field = read;
  return f;
}

INSTANTIATE_TEST_SUITE_P(
    Wire, HidFault,
    ::testing::Values(FaultCase{"timeout", At(60, &TransportFaults::timeout_from_read), "no answer within"},
                      FaultCase{"short", At(60, &TransportFaults::short_read_at), "short report: 17 of 64"},
                      FaultCase{"corrupt", At(60, &TransportFaults::corrupt_read_at), "corrupt report"},
                      FaultCase{"checksum", At(60, &TransportFaults::bad_checksum_at), "corrupt report"},
                      FaultCase{"stale", At(60, &TransportFaults::stale_read_at), "stale report"},
                      FaultCase{"unplug", At(60, &TransportFaults::unplug_at_read), "device disconnected"},
                      // The host's reports vanish: the device watchdog (50 ms) forces the gate low.
                      FaultCase{"silent_host", At(5, &TransportFaults::drop_writes_from), "watchdog"}),
    [](const auto& info) { return std::string(info.param.name); });

TEST(HidBench, LostReportsAreNoticed) {
  const auto e = BuildOrDie(OpenLoopJson(0.2, 1000));
  Rig rig(e);
  ASSERT_TRUE(rig.bench->Configure(e.run).ok());
  ASSERT_TRUE(rig.bench->Start(nullptr).ok());
  ASSERT_TRUE(rig.bench->Apply(SwitchCommand::Pwm(0.5, 375)).ok());
  Measurement m;
  ASSERT_TRUE(rig.bench->AdvanceTo(0.01, &m).ok());
  // Reports the host never read (a full OS buffer that dropped them) leave a gap in the sequence.
  std::array<std::uint8_t, 64> buf;
  size_t got;
  auto side = rig.device->Connect();
  ASSERT_EQ(side->Read(0, buf.data(), buf.size(), &got, 0), IoStatus::kOk);
  Status st = rig.bench->AdvanceTo(0.02, &m);
  EXPECT_EQ(st.code(), StatusCode::kDataLoss);
  EXPECT_NE(st.message().find("lost 1 report"), std::string::npos) << st.message();
  ExpectSafe(*rig.device);
}

TEST(HidBench, DeviceOvercurrentTripFailsTheRun) {
  const auto e = BuildOrDie(OpenLoopJson(0.2, 1000, 375, 0.9));
  HidBenchOptions opt;
  opt.max_current_A = 0.5;  // the device trips at 0.5 A; duty 0.9 at 24 V heads for ~1.6 A
  Rig rig(e, {}, opt);
  Ran r = RunOn(e, *rig.bench);
  EXPECT_EQ(r.summary.termination, experiment::RunSummary::Termination::kFailed);
  EXPECT_NE(r.summary.message.find("overcurrent"), std::string::npos) << r.summary.message;
  ASSERT_FALSE(r.trace.i_A.empty());
  EXPECT_GT(r.trace.i_A.back(), 0.45);  // the last sample is at the trip
  ExpectSafe(*rig.device);
}

TEST(HidBench, HungHostIsCaughtByTheDeviceWatchdog) {
  const auto e = BuildOrDie(OpenLoopJson(1.0, 1000));
  Rig rig(e);
  ASSERT_TRUE(rig.bench->Configure(e.run).ok());
  ASSERT_TRUE(rig.bench->Start(nullptr).ok());
  ASSERT_TRUE(rig.bench->Apply(SwitchCommand::Pwm(0.5, 375)).ok());
  Measurement m;
  ASSERT_TRUE(rig.bench->AdvanceTo(0.01, &m).ok());
  EXPECT_TRUE(rig.device->pwm_running());
  rig.device->RunFor(0.2);  // the host stops (a hung loop): 200 ms of device time without a host report
  ExpectSafe(*rig.device);
  ASSERT_EQ(rig.device->faults().size(), 1u);
  EXPECT_EQ(rig.device->faults()[0], hid::FaultCode::kWatchdog);
}

TEST(HidBench, ReconnectsAfterAnUnplug) {
  const auto e = BuildOrDie(OpenLoopJson(0.1, 1000));
  Rig rig(e, At(30, &TransportFaults::unplug_at_read));
  Ran first = RunOn(e, *rig.bench);
  EXPECT_FALSE(first.summary.ok());
  rig.device->Replug();
  Ran second = RunOn(e, *rig.bench);
  EXPECT_TRUE(second.summary.ok()) << second.summary.message;
  EXPECT_EQ(second.trace.size(), 101u);
}

TEST(HidBench, OnDeviceLoopsHoldTheCurrent) {
  const auto e = BuildOrDie(OpenLoopJson(1.0, 1000));
  for (hid::LoopMode mode : {hid::LoopMode::kPi, hid::LoopMode::kHysteresis}) {
    Rig rig(e);
    ASSERT_TRUE(rig.bench->Configure(e.run).ok());
    ASSERT_TRUE(rig.bench->Start(nullptr).ok());
    hid::SetLoop loop;
    loop.mode = mode;
    loop.setpoint = 1.0f;
    loop.band_A = 0.04f;
    loop.kp_V_per_A = 377.0f;
    loop.ki_V_per_A_s = 40.8e3f;
    loop.carrier_Hz = 20e3f;
    loop.loop_rate_Hz = 20'000;
    ASSERT_TRUE(rig.bench->SetDeviceLoop(loop).ok());
    Measurement m;
    double lo = 1e9, hi = -1e9;
    for (int k = 100; k <= 300; ++k) {  // 0.1 .. 0.3 s, after the rise
      ASSERT_TRUE(rig.bench->AdvanceTo(k * 1e-3, &m).ok());
      lo = std::min(lo, m.current_A);
      hi = std::max(hi, m.current_A);
    }
    EXPECT_GT(lo, 0.95) << int(mode);
    EXPECT_LT(hi, 1.05) << int(mode);
    // The host cannot drive the gate while the device loop has it.
    EXPECT_EQ(rig.bench->Apply(SwitchCommand::Gate(1)).code(), StatusCode::kFailedPrecondition);
    ASSERT_TRUE(rig.bench->Stop().ok());
    ExpectSafe(*rig.device);
  }
}

TEST(HidBench, RefusesWhatTheDeviceCannotDo) {
  const auto e = BuildOrDie(OpenLoopJson(0.1, 50'000));
  Rig rig(e);
  RunConfig rc = e.run;
  Status st = rig.bench->Configure(rc);  // 50 kHz recording > 20 kHz
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(st.message().find("sample_rate_Hz"), std::string::npos) << st.message();
  rc.sample_rate_Hz = 1000;
  rc.supply_V = 60;
  st = rig.bench->Configure(rc);
  EXPECT_NE(st.message().find("supply_V"), std::string::npos) << st.message();
  rc.supply_V = 24;
  ASSERT_TRUE(rig.bench->Configure(rc).ok());
  ASSERT_TRUE(rig.bench->Start(nullptr).ok());
  EXPECT_EQ(rig.bench->Apply(SwitchCommand::Gate(-1)).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(rig.bench->Apply(SwitchCommand::Pwm(0.5, 500e3)).code(), StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace vb::hw::testing
