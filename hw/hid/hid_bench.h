// HidBench: a microcontroller bench speaking the valvebench HID protocol (hw/hid/hid_protocol.h,
// docs/hw-protocol.md) behind the Bench interface.
//
// The device is the clock: it samples the coil current at the configured rate and streams SAMPLES reports;
// AdvanceTo(t) reads reports until the device has sampled through t, so a run is paced by the hardware (and
// an emulated device runs as fast as the host reads). Apply() sends SET_PWM / SET_GATE only when the command
// changes; a HEARTBEAT keeps the device watchdog fed when nothing else is sent. Every received report is
// checked: length, CRC-8, version, sequence number (a stale or repeated one, or a gap, fails the run), sample
// index continuity, and FAULT reports (the device already went to its safe state) fail the run with the
// device's reason. After an unplug the next Configure() reopens the device (by serial) and identifies again.
#pragma once

#include <array>
#include <memory>
#include <string>

#include "hw/bench.h"
#include "hw/hid/hid_protocol.h"
#include "hw/transport.h"

namespace vb::hw {

struct HidBenchOptions {
  std::string name = "hid";
  std::string driver = "low_side_flyback";  // the wiring; an H-bridge comes from the device's flags
  double watchdog_s = 0.05;                 // device watchdog; heartbeats every watchdog_s / 4 of device time
  int read_timeout_ms = 250;                // longest wait for one report
  int write_timeout_ms = 50;
  double default_sample_rate_Hz = 1000.0;   // when the run records nothing
  double max_current_A = 0.0;               // the device's own trip; 0 = its maximum
  double max_supply_V = 0.0;                // 0 = what the device reports
  int reopen_attempts = 3;                  // reconnects tried by Configure() after an unplug
};

class HidBench final : public Bench {
 public:
  // Identifies the device (IDENTIFY -> IDENTITY) and derives the capabilities from its answer.
  static StatusOr<std::unique_ptr<HidBench>> Open(std::unique_ptr<Transport> transport, HidBenchOptions options);

  const Capabilities& capabilities() const override { return caps_; }
  Status Configure(const RunConfig& config) override;
  Status Start(SampleSink* sink) override;
  Status Apply(const SwitchCommand& command) override;
  Status AdvanceTo(double t_s, Measurement* m) override;
  Status Stop() override;
  void SafeState() noexcept override;
  LoopStats loop_stats() const override { return stats_; }

  const hid::Identity& identity() const { return id_; }
  // Hands the current loop to the device (the fast inner loop: open loop, hysteresis or PI at the device's
  // rate); LoopMode::kHost gives the gate back to Apply(). Needs a running bench; answers with the ACK.
  Status SetDeviceLoop(const hid::SetLoop& loop);

 private:
  HidBench(std::unique_ptr<Transport> transport, HidBenchOptions options);
  Status Identify();
  Status Send(const hid::Report& r);
  // Reads one report and checks header and sequence; *h gets the header.
  Status Receive(hid::Report* r, hid::Header* h);
  // Handles a report received while running (samples, faults). Non-OK fails the run.
  Status Handle(const hid::Report& r, const hid::Header& h);
  // Sends `r` and waits for its ACK, handling samples and faults meanwhile.
  Status Command(const hid::Report& r, hid::Type type);
  void Emit(std::uint32_t index);
  Status Lost(Status st);  // notes an unplug, goes safe, returns st

  struct Sample {
    double i_A = 0.0;
    std::int8_t gate = 0;
  };

  std::unique_ptr<Transport> transport_;
  HidBenchOptions opt_;
  hid::Identity id_;
  Capabilities caps_;
  RunConfig config_;
  SampleSink* sink_ = nullptr;
  double rate_Hz_ = 0.0;
  int per_report_ = 1;
  bool running_ = false, configured_ = false, need_reopen_ = false, device_loop_ = false;
  Status fault_;                              // latched device fault of this run

  std::uint32_t host_seq_ = 0;
  bool have_dev_seq_ = false;
  std::uint32_t next_dev_seq_ = 0;
  std::uint32_t next_index_ = 0;               // the next sample index the device must send
  std::int64_t emitted_ = -1;                  // the last sample index given to the sink
  std::int64_t target_ = 0;                    // samples up to this index go to the sink as they arrive
  std::uint32_t last_write_index_ = 0;         // device time of the last host report (watchdog)
  static constexpr std::size_t kRing = 64;     // > 2 reports of samples
  std::array<Sample, kRing> ring_{};
  SwitchCommand last_cmd_;
  bool have_cmd_ = false;
  LoopStats stats_;
};

}  // namespace vb::hw
