#include "common/format.h"
#include "hw/device_bench.h"
#include "hw/u3/u3_bench.h"

#include <algorithm>
#include <cmath>

namespace vb::hw {

StatusOr<U3Pwm> RealiseU3Pwm(double carrier_Hz) {
  if (!(carrier_Hz > 0.0)) return Status::InvalidArgument("carrier_Hz: must be > 0");
  double best_below = 0.0, best_above = 1e300;
  for (std::uint8_t mode : {u3::kTimerModePwm16, u3::kTimerModePwm8}) {
    const double steps = mode == u3::kTimerModePwm16 ? 65536.0 : 256.0;
    for (std::uint8_t base = 0; base <= 6; ++base) {
      const int divisors = base >= 3 ? 256 : 1;
      for (int d = 1; d <= divisors; ++d) {
        u3::TimerClock c{base, static_cast<std::uint8_t>(base >= 3 ? d % 256 : 0)};
        const double f = u3::TimerClockHz(c) / steps;
        if (std::abs(f - carrier_Hz) <= 1e-9 * carrier_Hz) return U3Pwm{c, mode, f};
        if (f < carrier_Hz) best_below = std::max(best_below, f);
        if (f > carrier_Hz) best_above = std::min(best_above, f);
      }
    }
  }
  return Status::NotFound("carrier_Hz: the U3's timer cannot make " + FormatNumber(carrier_Hz) + " Hz exactly (nearest: " +
                          FormatNumber(best_below) + " Hz and " + FormatNumber(best_above) + " Hz)");
}

std::uint16_t U3TimerValue(std::uint8_t mode, double duty) {
  duty = std::clamp(duty, 0.0, 1.0);
  if (mode == u3::kTimerModePwm8) {
    const long low = std::clamp(std::lround(256.0 * (1.0 - duty)), 0L, 255L);
    return static_cast<std::uint16_t>(low << 8);
  }
  return static_cast<std::uint16_t>(std::clamp(std::lround(65536.0 * (1.0 - duty)), 0L, 65535L));
}

double U3Duty(std::uint8_t mode, std::uint16_t value) {
  if (mode == u3::kTimerModePwm8) return (256.0 - (value >> 8)) / 256.0;
  return (65536.0 - value) / 65536.0;
}

U3Bench::U3Bench(std::unique_ptr<Transport> transport, U3BenchOptions options)
    : transport_(std::move(transport)), opt_(std::move(options)) {}

StatusOr<std::unique_ptr<U3Bench>> U3Bench::Open(std::unique_ptr<Transport> transport, U3BenchOptions options) {
  if (transport == nullptr) return Status::InvalidArgument("transport: none given");
  if (options.timer_pin < 4 || options.timer_pin > 7)
    return Status::InvalidArgument("timer_pin: must be FIO4..FIO7, got " + std::to_string(options.timer_pin));
  if (options.ain_channel > 3) return Status::InvalidArgument("ain_channel: must be AIN0..AIN3");
  if (!(options.amps_per_volt > 0.0)) return Status::InvalidArgument("amps_per_volt: must be > 0");
  if (options.watchdog_s < 1) return Status::InvalidArgument("watchdog_s: must be >= 1 (whole seconds)");
  std::unique_ptr<U3Bench> b(new U3Bench(std::move(transport), std::move(options)));
  VB_RETURN_IF_ERROR(b->Identify());
  return b;
}

Status U3Bench::Identify() {
  // Drain what an interrupted session left on the response pipe.
  u3::Packet junk;
  std::size_t got = 0;
  for (int k = 0; k < 64; ++k)
    if (transport_->Read(u3::kEpResponseIn, junk.data(), u3::kMaxPacket, &got, 0) != IoStatus::kOk) break;
  u3::Packet resp;
  VB_RETURN_IF_ERROR(Transact(u3::EncodeConfigU3Read(), u3::kConfigU3ResponseSize, &resp, "ConfigU3"));
  u3::DeviceInfo info;
  VB_RETURN_IF_ERROR(u3::DecodeConfigU3Response(resp.data(), resp.size(), &info).WithContext(transport_->Describe()));
  if (opt_.serial != 0 && info.serial != opt_.serial)
    return Status::FailedPrecondition(transport_->Describe() + ": serial " + std::to_string(info.serial) +
                                      ", configured " + std::to_string(opt_.serial));
  if (configured_ && info.serial != info_.serial)
    return Status::FailedPrecondition(transport_->Describe() + ": a different U3 (serial " +
                                      std::to_string(info.serial) + ") answered after the reconnect");
  info_ = info;
  timers_on_ = -1;
  have_clock_ = false;
  caps_ = Capabilities{};
  caps_.kind = "u3";
  caps_.driver = "low_side_flyback";
  caps_.max_supply_V = opt_.max_supply_V;
  caps_.min_carrier_Hz = u3::TimerClockHz(u3::TimerClock{3, 0}) / 65536.0;  // 1 MHz / 256 / 65536
  caps_.max_carrier_Hz = u3::TimerClockHz(u3::TimerClock{2, 0}) / 256.0;    // 48 MHz / 256
  caps_.max_sample_rate_Hz = opt_.max_sample_rate_Hz;
  caps_.max_control_rate_Hz = opt_.max_control_rate_Hz;
  caps_.max_current_A = opt_.max_current_A;
  caps_.serial = std::to_string(info_.serial);
  return Status::Ok();
}

Status U3Bench::Transact(const u3::Packet& out, std::size_t resp_size, u3::Packet* resp, const char* what) {
  IoStatus io = transport_->Write(u3::kEpCommandOut, out.data(), out.size(), opt_.write_timeout_ms);
  if (io == IoStatus::kDisconnected) need_reopen_ = true;
  if (io != IoStatus::kOk) return TransportError(io, what, *transport_, opt_.write_timeout_ms);
  last_command_index_ = next_index_;
  std::size_t got = 0;
  io = transport_->Read(u3::kEpResponseIn, resp->data(), u3::kMaxPacket, &got, opt_.read_timeout_ms);
  if (io == IoStatus::kDisconnected) need_reopen_ = true;
  if (io != IoStatus::kOk) return TransportError(io, what, *transport_, opt_.read_timeout_ms);
  resp->Resize(got);
  if (got == 2 && (*resp)[0] == u3::kBadChecksumReply && (*resp)[1] == u3::kBadChecksumReply)
    return Status::DataLoss(std::string(what) + ": " + transport_->Describe() + " rejected the command's checksum");
  if (resp_size > 0 && got != resp_size)
    return Status::DataLoss(std::string(what) + ": " + transport_->Describe() + ": short packet: " +
                            std::to_string(got) + " of " + std::to_string(resp_size) + " bytes");
  return Status::Ok();
}

Status U3Bench::Lost(Status st) {
  SafeState();
  return st;
}

Status U3Bench::Configure(const RunConfig& config) {
  if (running_) return Status::FailedPrecondition("bench " + opt_.name + " is running");
  if (need_reopen_) {
    VB_RETURN_IF_ERROR(Reconnect(*transport_, opt_.reopen_attempts, [this] { return Identify(); }, opt_.name));
    need_reopen_ = false;
  }
  VB_RETURN_IF_ERROR(CheckSupply(config.supply_V, caps_.max_supply_V, opt_.name));
  const double rate = config.sample_rate_Hz > 0.0 ? config.sample_rate_Hz : opt_.default_sample_rate_Hz;
  if (rate > caps_.max_sample_rate_Hz)
    return Status::FailedPrecondition("sample_rate_Hz: " + FormatNumber(rate) + " Hz exceeds bench " + opt_.name + "'s " +
                                      FormatNumber(caps_.max_sample_rate_Hz) + " Hz");
  // Scan rate = clock / ScanInterval exactly, from the 4 MHz clock, the 48 MHz one, or 4 MHz / 256.
  u3::StreamConfig sc;
  bool found = false;
  for (auto [mhz48, div256] : {std::pair{false, false}, std::pair{true, false}, std::pair{false, true}}) {
    const double clock = (mhz48 ? 48e6 : 4e6) / (div256 ? 256.0 : 1.0);
    const double interval = clock / rate;
    if (std::abs(interval - std::round(interval)) < 1e-9 * interval && interval >= 1.0 && interval <= 65535.0) {
      sc.clock_48MHz = mhz48;
      sc.divide_by_256 = div256;
      sc.scan_interval = static_cast<std::uint16_t>(std::lround(interval));
      found = true;
      break;
    }
  }
  if (!found)
    return Status::FailedPrecondition("sample_rate_Hz: " + FormatNumber(rate) + " Hz is not 4 MHz or 48 MHz divided by a "
                                      "whole ScanInterval (1..65535); bench " + opt_.name);
  scans_per_packet_ = std::clamp(static_cast<int>(std::ceil(rate / opt_.max_control_rate_Hz)), 1, 12);
  sc.samples_per_packet = static_cast<std::uint8_t>(2 * scans_per_packet_);
  sc.channels = {{opt_.ain_channel, u3::kNegChannelSingleEnded}, {u3::kStreamChannelFioEio, 0}};

  u3::Packet resp;
  // The gate pin digital and low, the shunt input analog, no timer until a PWM command.
  VB_RETURN_IF_ERROR(SetTimers(0));
  VB_RETURN_IF_ERROR(DigitalGate(0));
  u3::Watchdog wd;
  wd.enable = true;
  wd.reset_on_timeout = true;
  wd.timeout_s = opt_.watchdog_s;
  Status st = Transact(u3::Encode(wd), u3::kWatchdogSize, &resp, "Watchdog");
  if (st.ok()) {
    u3::Watchdog back;
    st = u3::DecodeWatchdog(resp.data(), resp.size(), &back);
    if (st.ok() && resp[6] != 0) st = Status::FailedPrecondition("Watchdog: device errorcode " + u3::ErrorcodeName(resp[6]));
  }
  if (!st.ok()) return Lost(st.WithContext("bench " + opt_.name));
  st = Transact(u3::Encode(sc), u3::kStreamConfigResponseSize, &resp, "StreamConfig");
  if (st.ok()) st = u3::CheckExtended(resp.data(), resp.size(), 0xF8, 0x11, u3::kStreamConfigResponseSize);
  if (st.ok() && resp[6] != 0) st = Status::FailedPrecondition("StreamConfig: device errorcode " + u3::ErrorcodeName(resp[6]));
  if (!st.ok()) return Lost(st.WithContext("bench " + opt_.name));
  stream_ = sc;
  rate_Hz_ = rate;
  config_ = config;
  configured_ = true;
  return Status::Ok();
}

Status U3Bench::SetTimers(int enabled) {
  if (timers_on_ == enabled) return Status::Ok();
  u3::ConfigIO c;
  c.timers_enabled = static_cast<std::uint8_t>(enabled);
  c.pin_offset = opt_.timer_pin;
  c.fio_analog = static_cast<std::uint8_t>(1u << opt_.ain_channel);
  u3::Packet resp;
  VB_RETURN_IF_ERROR(Transact(u3::Encode(c), u3::kConfigIOSize, &resp, "ConfigIO"));
  u3::ConfigIO back;
  VB_RETURN_IF_ERROR(u3::DecodeConfigIO(resp.data(), resp.size(), &back));
  if (resp[6] != 0) return Status::FailedPrecondition("ConfigIO: device errorcode " + u3::ErrorcodeName(resp[6]));
  if (back.timers_enabled != c.timers_enabled)
    return Status::FailedPrecondition("ConfigIO: the device kept " + std::to_string(back.timers_enabled) + " timer(s)");
  timers_on_ = enabled;
  return Status::Ok();
}

Status U3Bench::DigitalGate(int level) {
  VB_RETURN_IF_ERROR(SetTimers(0));
  u3::FeedbackBuilder fb;
  fb.BitDirWrite(opt_.timer_pin, true);
  fb.BitStateWrite(opt_.timer_pin, level != 0);
  u3::Packet resp;
  VB_RETURN_IF_ERROR(Transact(fb.Finish(), fb.ResponseSize(), &resp, "Feedback"));
  return u3::CheckFeedbackResponse(resp.data(), resp.size(), fb.ResponseSize());
}

Status U3Bench::Heartbeat() {
  u3::FeedbackBuilder fb;  // no IOTypes: answered, and it resets the device's watchdog
  u3::Packet resp;
  VB_RETURN_IF_ERROR(Transact(fb.Finish(), fb.ResponseSize(), &resp, "Feedback"));
  return u3::CheckFeedbackResponse(resp.data(), resp.size(), fb.ResponseSize());
}

Status U3Bench::Start(SampleSink* sink) {
  if (!configured_) return Status::FailedPrecondition("bench " + opt_.name + ": Configure() first");
  sink_ = sink;
  have_cmd_ = false;
  stats_ = LoopStats{};
  next_index_ = 0;
  emitted_ = -1;
  target_ = 0;
  have_packet_number_ = false;
  u3::Packet resp;
  Status st = Transact(u3::NormalCommand(u3::kStreamStart), 4, &resp, "StreamStart");
  if (st.ok()) st = u3::CheckNormal(resp.data(), resp.size(), u3::kStreamStart + 1).WithContext("StreamStart");
  if (!st.ok()) return Lost(st);
  last_command_index_ = 0;
  running_ = true;
  return Status::Ok();
}

void U3Bench::Emit(std::uint32_t index) {
  const Sample& s = ring_[index % kRing];
  emitted_ = index;
  if (sink_ == nullptr) return;
  sink_->OnSample(CurrentOnlySample(index / rate_Hz_, s.gate, s.i_A));
}

Status U3Bench::ReadStream() {
  u3::Packet p;
  std::size_t got = 0;
  const IoStatus io = transport_->Read(u3::kEpStreamIn, p.data(), u3::kMaxPacket, &got, opt_.read_timeout_ms);
  if (io == IoStatus::kDisconnected) need_reopen_ = true;
  if (io != IoStatus::kOk) return TransportError(io, "stream read", *transport_, opt_.read_timeout_ms);
  u3::StreamData d;
  VB_RETURN_IF_ERROR(
      u3::DecodeStreamData(p.data(), got, stream_.samples_per_packet, &d).WithContext(transport_->Describe()));
  if (have_packet_number_ && d.packet_number != next_packet_) {
    if (static_cast<std::uint8_t>(d.packet_number + 1) == next_packet_)
      return Status::DataLoss(transport_->Describe() + ": stale stream packet (number " +
                              std::to_string(d.packet_number) + " again)");
    return Status::DataLoss(transport_->Describe() + ": lost " +
                            std::to_string(static_cast<std::uint8_t>(d.packet_number - next_packet_)) +
                            " stream packet(s) (number " + std::to_string(d.packet_number) + ", expected " +
                            std::to_string(next_packet_) + ")");
  }
  if (d.errorcode != 0)
    return Status::Aborted(transport_->Describe() + ": stream errorcode " + u3::ErrorcodeName(d.errorcode) +
                            " (backlog " + std::to_string(d.backlog) + ")");
  have_packet_number_ = true;
  next_packet_ = static_cast<std::uint8_t>(d.packet_number + 1);
  const double amps_per_count = u3::kNominalAinSlope_V * opt_.amps_per_volt;
  for (int k = 0; k < scans_per_packet_; ++k) {
    const std::uint32_t idx = next_index_ + static_cast<std::uint32_t>(k);
    const std::uint16_t fio = d.samples[2 * k + 1];
    ring_[idx % kRing] = Sample{d.samples[2 * k] * amps_per_count, static_cast<std::int8_t>((fio >> opt_.timer_pin) & 1)};
    if (static_cast<std::int64_t>(idx) <= target_) Emit(idx);
  }
  next_index_ += static_cast<std::uint32_t>(scans_per_packet_);
  return Status::Ok();
}

Status U3Bench::AdvanceTo(double t_s, Measurement* m) {
  if (!running_) return Status::FailedPrecondition("bench " + opt_.name + " is not running");
  target_ = static_cast<std::int64_t>(std::floor(t_s * rate_Hz_ + 1e-6));
  while (emitted_ < target_ && emitted_ + 1 < static_cast<std::int64_t>(next_index_))
    Emit(static_cast<std::uint32_t>(emitted_ + 1));
  while (static_cast<std::int64_t>(next_index_) <= target_) {
    Status st = ReadStream();
    if (!st.ok()) return Lost(st);
    // Feed the device's watchdog at a quarter of its period of silence.
    if ((next_index_ - last_command_index_) >= opt_.watchdog_s * 0.25 * rate_Hz_) {
      st = Heartbeat();
      if (!st.ok()) return Lost(st);
    }
  }
  ++stats_.ticks;
  if (m != nullptr)
    FillCurrentOnlyMeasurement(t_s, ring_[static_cast<std::size_t>(target_) % kRing].i_A, config_.supply_V, m);
  return Status::Ok();
}

Status U3Bench::Apply(const SwitchCommand& c) {
  if (!running_) return Status::FailedPrecondition("bench " + opt_.name + " is not running");
  if (have_cmd_ && c.mode == last_cmd_.mode && !c.restart_carrier &&
      (c.mode == SwitchCommand::Mode::kGate ? c.gate == last_cmd_.gate
                                            : c.duty == last_cmd_.duty && c.carrier_Hz == last_cmd_.carrier_Hz))
    return Status::Ok();
  Status st;
  if (c.mode == SwitchCommand::Mode::kGate) {
    if (c.gate < 0 || c.gate > 1)
      return Status::FailedPrecondition("gate " + std::to_string(c.gate) + " needs an H-bridge; bench " + opt_.name +
                                        " has low_side_flyback");
    st = DigitalGate(c.gate);
  } else if (c.duty <= 0.0) {
    st = DigitalGate(0);
  } else {
    if (!have_clock_ || c.carrier_Hz != pwm_.carrier_Hz) {
      auto pwm = RealiseU3Pwm(c.carrier_Hz);
      if (!pwm.ok()) return Status::FailedPrecondition(pwm.status().message() + " (bench " + opt_.name + ")");
      u3::Packet resp;
      st = Transact(u3::Encode(pwm->clock), u3::kConfigTimerClockSize, &resp, "ConfigTimerClock");
      u3::TimerClock back;
      if (st.ok()) st = u3::DecodeTimerClock(resp.data(), resp.size(), &back, nullptr);
      if (st.ok() && resp[6] != 0)
        st = Status::FailedPrecondition("ConfigTimerClock: device errorcode " + u3::ErrorcodeName(resp[6]));
      if (!st.ok()) return Lost(st);
      pwm_ = *pwm;
      have_clock_ = true;
      timers_on_ = timers_on_ == 1 ? -1 : timers_on_;  // a new clock: re-enable the timer (restarts the carrier)
    }
    if (c.restart_carrier) timers_on_ = -1;
    st = SetTimers(1);
    if (st.ok()) {
      u3::FeedbackBuilder fb;
      timer_value_ = U3TimerValue(pwm_.mode, c.duty);
      fb.Timer0Config(pwm_.mode, timer_value_);
      u3::Packet resp;
      st = Transact(fb.Finish(), fb.ResponseSize(), &resp, "Feedback");
      if (st.ok()) st = u3::CheckFeedbackResponse(resp.data(), resp.size(), fb.ResponseSize());
    }
  }
  if (!st.ok()) return Lost(st.WithContext("bench " + opt_.name));
  last_cmd_ = c;
  have_cmd_ = true;
  return Status::Ok();
}

Status U3Bench::Stop() {
  if (!running_) return Status::Ok();
  running_ = false;
  SafeState();
  u3::Packet resp;
  Status st = Transact(u3::NormalCommand(u3::kStreamStop), 4, &resp, "StreamStop");
  if (st.ok()) st = u3::CheckNormal(resp.data(), resp.size(), u3::kStreamStop + 1).WithContext("StreamStop");
  return st;
}

void U3Bench::SafeState() noexcept {
  // Timer off and the pin driven low; if the device does not answer, its watchdog resets it (outputs become
  // inputs and the gate resistor pulls the gate low).
  have_cmd_ = false;
  timers_on_ = -1;
  (void)DigitalGate(0);
}

}  // namespace vb::hw
