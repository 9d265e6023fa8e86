// U3Bench: a LabJack U3 wired to a valve behind the Bench interface (docs/wiring.md). Timer0 in PWM mode
// drives the MOSFET gate on FIO<timer_pin>; the shunt amplifier's output goes to AIN<ain_channel>; the stream
// scans that input and the FIO states (so every sample carries the gate level) at the recording rate.
//
// The device is the clock, as with the HID bench: AdvanceTo(t) reads stream packets until the U3 has scanned
// through t. Apply() talks to the device only when the command changes: a new carrier sets the timer clock
// (ConfigTimerClock), a new duty the timer value (Feedback Timer0Config); gate-level commands and duty 0 switch
// the timer off and drive the pin as a digital output. Carriers the timer cannot realise exactly are refused
// (FailedPrecondition naming the nearest ones); duties are rounded to the timer's resolution (1/256 in 8-bit
// mode). Every packet is checked (size, Checksum8, Checksum16, command bytes, errorcode, the stream's packet
// counter: a stale or lost packet fails the run). The U3's own watchdog is armed to reset the device (all
// outputs become inputs, the gate resistor pulls the gate low) when the host has been silent for watchdog_s.
// After an unplug the next Configure() reopens the device and checks it is the same serial number.
#pragma once

#include <array>
#include <memory>
#include <string>

#include "hw/bench.h"
#include "hw/transport.h"
#include "hw/u3/u3_protocol.h"

namespace vb::hw {

struct U3BenchOptions {
  std::string name = "u3";
  std::uint32_t serial = 0;              // 0 = whichever U3 the transport opened
  std::uint8_t timer_pin = 4;            // Timer0 (the gate) on FIO4: ConfigIO TimerCounterPinOffset
  std::uint8_t ain_channel = 0;          // shunt amplifier output on AIN0 (FIO0, set analog)
  double amps_per_volt = 1.0;            // current per AIN volt: 1 / (R_shunt * amplifier gain)
  double max_supply_V = 24.0;            // the bench's supply (the U3 cannot know it)
  double max_current_A = 2.0;            // what the wiring is rated for
  double max_sample_rate_Hz = 10'000.0;  // stream scans (2 channels each)
  double max_control_rate_Hz = 1'000.0;  // one host decision per stream packet at best
  int read_timeout_ms = 250;
  int write_timeout_ms = 50;
  std::uint16_t watchdog_s = 1;          // U3 watchdog: whole seconds, >= 1
  double default_sample_rate_Hz = 1000.0;
  int reopen_attempts = 3;
};

// A realisable PWM: timer clock, mode (8/16-bit) and the frequency they give.
struct U3Pwm {
  u3::TimerClock clock;
  std::uint8_t mode = u3::kTimerModePwm8;
  double carrier_Hz = 0.0;
};
// The exact realisation of carrier_Hz (relative error < 1e-9), preferring 16-bit mode; NotFound otherwise,
// naming the nearest realisable carriers.
StatusOr<U3Pwm> RealiseU3Pwm(double carrier_Hz);
// Timer value for a duty in (0, 1]: the low time out of 65536 (16-bit) or 256 (8-bit, upper byte).
std::uint16_t U3TimerValue(std::uint8_t mode, double duty);
double U3Duty(std::uint8_t mode, std::uint16_t value);

class U3Bench final : public Bench {
 public:
  // Reads the device's identity (ConfigU3) and checks it is a U3 (and the configured serial).
  static StatusOr<std::unique_ptr<U3Bench>> Open(std::unique_ptr<Transport> transport, U3BenchOptions options);

  const Capabilities& capabilities() const override { return caps_; }
  Status Configure(const RunConfig& config) override;
  Status Start(SampleSink* sink) override;
  Status Apply(const SwitchCommand& command) override;
  Status AdvanceTo(double t_s, Measurement* m) override;
  Status Stop() override;
  void SafeState() noexcept override;
  LoopStats loop_stats() const override { return stats_; }

  const u3::DeviceInfo& info() const { return info_; }

 private:
  U3Bench(std::unique_ptr<Transport> transport, U3BenchOptions options);
  Status Identify();
  // Sends an extended command and reads its response (expected size) into *resp.
  Status Transact(const u3::Packet& out, std::size_t resp_size, u3::Packet* resp, const char* what);
  Status SetTimers(int enabled);
  Status DigitalGate(int level);
  Status Heartbeat();
  Status ReadStream();
  void Emit(std::uint32_t index);
  Status Lost(Status st);

  struct Sample {
    double i_A = 0.0;
    std::int8_t gate = 0;
  };

  std::unique_ptr<Transport> transport_;
  U3BenchOptions opt_;
  u3::DeviceInfo info_;
  Capabilities caps_;
  RunConfig config_;
  u3::StreamConfig stream_;
  SampleSink* sink_ = nullptr;
  double rate_Hz_ = 0.0;
  int scans_per_packet_ = 1;
  bool configured_ = false, running_ = false, need_reopen_ = false;
  int timers_on_ = -1;                       // -1 unknown
  bool have_clock_ = false;
  U3Pwm pwm_;
  std::uint16_t timer_value_ = 0;
  SwitchCommand last_cmd_;
  bool have_cmd_ = false;

  bool have_packet_number_ = false;
  std::uint8_t next_packet_ = 0;
  std::uint32_t next_index_ = 0;             // the next scan index the stream delivers
  std::int64_t emitted_ = -1, target_ = 0;
  std::uint32_t last_command_index_ = 0;     // scan index of the last command (the watchdog)
  static constexpr std::size_t kRing = 64;
  std::array<Sample, kRing> ring_{};
  LoopStats stats_;
};

}  // namespace vb::hw
