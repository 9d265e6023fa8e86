// The device side of the valvebench HID protocol, byte for byte, with the valve model behind it: what the
// firmware of a microcontroller bench does (docs/hw-protocol.md), for tests without hardware.
//
// Free-running: the device produces a SAMPLES report whenever the host reads and nothing else is queued, so
// device time advances with the host's reads and a run takes no wall time. Host reports act at the device
// time of the last sample sent. The watchdog, overcurrent trip, fault latching and the on-device current
// loops (open loop, hysteresis, PI) work as specified; the valve is an EmulatedBench (its PWM peripheral and
// event-exact model), the current is quantised to the protocol's counts.
#pragma once

#include <deque>
#include <memory>
#include <vector>

#include "hw/emulated_bench.h"
#include "hw/hid/hid_protocol.h"
#include "hw/transport.h"

namespace vb::hw::testing {

struct HidDeviceOptions {
  hid::Identity identity = DefaultIdentity();
  EmulatedBenchOptions valve;      // the model behind the device
  double supply_V = 24.0;          // what the bench's supply delivers
  static hid::Identity DefaultIdentity();
};

class HidDeviceEmulator {
 public:
  explicit HidDeviceEmulator(HidDeviceOptions options);
  HidDeviceEmulator(const HidDeviceEmulator&) = delete;
  HidDeviceEmulator& operator=(const HidDeviceEmulator&) = delete;

  // A cable to the device: the Transport the host's protocol code uses. The device must outlive it.
  std::unique_ptr<Transport> Connect();

  // Test controls and probes.
  void Unplug();                  // USB gone: the device loses power (gate low, state reset) until Replug()
  void Replug();
  void RunFor(double seconds);    // device time passes without the host (a hung host): the watchdog acts
  int gate() const;               // what the MOSFET gate sees now
  bool pwm_running() const { return pwm_running_; }
  bool sampling() const { return sampling_; }
  double t_s() const { return t_s_; }
  double current_A() const { return i_A_; }
  const std::vector<hid::FaultCode>& faults() const { return faults_; }
  int bad_reports() const { return bad_reports_; }
  int host_reports() const { return host_reports_; }

 private:
  class Cable;
  IoStatus HostWrite(const std::uint8_t* data, std::size_t size);
  IoStatus HostRead(std::uint8_t* buf, std::size_t capacity, std::size_t* received);
  void Handle(const hid::Report& r, const hid::Header& h);
  void Ack(const hid::Header& h, hid::AckResult result, std::uint8_t field = 0);
  void Trip(hid::FaultCode code, float value);
  void GoSafe();
  void ProduceReport();
  void AdvanceValve(double t_s);
  void LoopTick();
  void Queue(const hid::Report& r) { out_.push_back(r); }

  HidDeviceOptions opt_;
  EmulatedBench valve_;
  bool plugged_ = true;
  std::uint32_t seq_ = 0;
  std::deque<hid::Report> out_;
  std::uint32_t last_host_seq_ = 0;
  // configuration
  bool configured_ = false, sampling_ = false, pwm_running_ = false, latched_ = false;
  hid::Configure cfg_;
  // time
  std::uint32_t next_index_ = 0;
  double t_s_ = 0.0, last_host_t_s_ = 0.0, i_A_ = 0.0;
  // on-device loop
  hid::SetLoop loop_;
  double next_loop_t_s_ = 0.0, integral_V_ = 0.0;
  int hyst_gate_ = 0;
  std::vector<hid::FaultCode> faults_;
  int bad_reports_ = 0, host_reports_ = 0;
};

}  // namespace vb::hw::testing
