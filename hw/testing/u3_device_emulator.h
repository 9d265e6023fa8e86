// The device side of the LabJack U3 low-level protocol (the subset U3Bench uses), byte for byte, with the
// valve model behind it: commands on endpoint 0x01, responses on 0x82, stream data on 0x83.
//
// Free-running like the HID emulator: a stream packet is produced when the host reads endpoint 0x83, so device
// time advances with the host's reads. Timer0 in PWM mode drives the valve's gate through the EmulatedBench's
// PWM peripheral at the frequency and duty the timer clock and value give; with the timer off the pin is a
// digital output. AIN counts follow the U3-LV's nominal single-ended slope; channel 193 returns the FIO
// states. A command whose checksums are wrong is answered 0xB8 0xB8. The watchdog resets the device (timers
// off, pins inputs, stream stopped) after its timeout of device time without a command.
#pragma once

#include <deque>
#include <memory>

#include "hw/emulated_bench.h"
#include "hw/transport.h"
#include "hw/u3/u3_protocol.h"

namespace vb::hw::testing {

struct U3DeviceOptions {
  EmulatedBenchOptions valve;
  double supply_V = 24.0;
  double amps_per_volt = 1.0;        // the shunt amplifier
  std::uint32_t serial = 320012345;
};

class U3DeviceEmulator {
 public:
  explicit U3DeviceEmulator(U3DeviceOptions options);
  U3DeviceEmulator(const U3DeviceEmulator&) = delete;
  U3DeviceEmulator& operator=(const U3DeviceEmulator&) = delete;

  std::unique_ptr<Transport> Connect();  // the device must outlive it

  void Unplug();
  void Replug();
  void RunFor(double seconds);           // device time passes without the host
  int gate() const;                      // what the MOSFET gate sees
  bool timer_running() const { return timers_ > 0; }
  bool streaming() const { return streaming_; }
  int resets() const { return resets_; }
  int bad_checksums() const { return bad_checksums_; }
  std::uint8_t timer_pin() const { return pin_offset_; }

 private:
  class Cable;
  IoStatus HostWrite(std::uint8_t ep, const std::uint8_t* data, std::size_t size);
  IoStatus HostRead(std::uint8_t ep, std::uint8_t* buf, std::size_t capacity, std::size_t* received);
  void Reset();
  void ApplyOutputs(bool restart_carrier = false);
  void ProducePacket();
  void Respond(const u3::Packet& p) { responses_.push_back(p); }

  U3DeviceOptions opt_;
  EmulatedBench valve_;
  bool plugged_ = true;
  std::deque<u3::Packet> responses_, responses_stream_;
  // device state
  int timers_ = 0;
  std::uint8_t pin_offset_ = 4, fio_analog_ = 0x0F;
  std::uint8_t fio_dir_ = 0, fio_state_ = 0;
  u3::TimerClock clock_;
  std::uint8_t timer_mode_ = u3::kTimerModePwm16;
  std::uint16_t timer_value_ = 0;
  u3::Watchdog watchdog_;
  u3::StreamConfig stream_;
  bool stream_configured_ = false, streaming_ = false;
  std::uint8_t packet_number_ = 0;
  std::uint64_t scan_ = 0;
  double t_s_ = 0.0, last_command_t_s_ = 0.0, i_A_ = 0.0;
  double timer_enabled_t_s_ = -1.0;  // a timer value written at the instant the timer starts applies at once
  int resets_ = 0, bad_checksums_ = 0;
};

}  // namespace vb::hw::testing
