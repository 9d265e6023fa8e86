#include "hw/testing/hid_device_emulator.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace vb::hw::testing {

hid::Identity HidDeviceOptions::DefaultIdentity() {
  hid::Identity id;
  id.firmware_version = 0x0100;
  id.flags = hid::kCapLoopOpen | hid::kCapLoopHysteresis | hid::kCapLoopPi;
  id.current_channels = 1;
  id.max_supply_mV = 48'000;
  id.min_pwm_Hz = 10.0f;
  id.max_pwm_Hz = 100'000.0f;
  id.max_sample_rate_Hz = 20'000;
  id.max_report_rate_Hz = 1000;
  id.max_inner_loop_Hz = 50'000;
  id.current_lsb_nA = 100'000;   // 0.1 mA per count: +/-3.2 A full scale
  id.max_current_mA = 3'000;
  std::strncpy(id.serial, "EMU-HID-0001", sizeof(id.serial));
  id.min_watchdog_ms = 5;
  return id;
}

class HidDeviceEmulator::Cable final : public Transport {
 public:
  explicit Cable(HidDeviceEmulator* d) : d_(d) {}
  IoStatus Write(std::uint8_t, const std::uint8_t* data, std::size_t size, int) override {
    return d_->HostWrite(data, size);
  }
  IoStatus Read(std::uint8_t, std::uint8_t* buf, std::size_t capacity, std::size_t* received, int) override {
    return d_->HostRead(buf, capacity, received);
  }
  Status Reopen() override {
    if (!d_->plugged_) return Status::Unavailable("no HID device with serial " + hid::SerialOf(d_->opt_.identity));
    return Status::Ok();
  }
  std::string Describe() const override { return "emulated hid " + hid::SerialOf(d_->opt_.identity); }

 private:
  HidDeviceEmulator* d_;
};

HidDeviceEmulator::HidDeviceEmulator(HidDeviceOptions options) : opt_(std::move(options)), valve_(opt_.valve) {
  seq_ = 0xFFFFFFF0u;  // near the wrap: the host must handle it
}

std::unique_ptr<Transport> HidDeviceEmulator::Connect() { return std::make_unique<Cable>(this); }

int HidDeviceEmulator::gate() const { return plugged_ ? valve_.simulator().gate() : 0; }

void HidDeviceEmulator::Unplug() {
  GoSafe();
  plugged_ = false;
  sampling_ = configured_ = latched_ = false;
  out_.clear();
}

void HidDeviceEmulator::Replug() {
  plugged_ = true;
  seq_ = 0;  // a power-on reset
}

void HidDeviceEmulator::GoSafe() {
  valve_.SafeState();
  pwm_running_ = false;
  loop_.mode = hid::LoopMode::kHost;
}

void HidDeviceEmulator::Trip(hid::FaultCode code, float value) {
  GoSafe();
  latched_ = true;
  faults_.push_back(code);
  hid::Fault f;
  f.code = code;
  f.sample_index = next_index_;
  f.value = value;
  Queue(hid::Encode(f, seq_++));
}

void HidDeviceEmulator::Ack(const hid::Header& h, hid::AckResult result, std::uint8_t field) {
  hid::Ack a;
  a.acked_type = h.type;
  a.acked_seq = h.seq;
  a.result = result;
  a.field_offset = field;
  Queue(hid::Encode(a, seq_++));
}

IoStatus HidDeviceEmulator::HostWrite(const std::uint8_t* data, std::size_t size) {
  if (!plugged_) return IoStatus::kDisconnected;
  hid::Header h;
  if (!hid::ParseHeader(data, size, &h).ok() || static_cast<std::uint8_t>(h.type) >= 0x80) {
    ++bad_reports_;
    hid::Fault f;  // a rejected report does not feed the watchdog and is not executed
    f.code = hid::FaultCode::kBadReport;
    f.sample_index = next_index_;
    f.value = size > 0 ? data[0] : 0;
    Queue(hid::Encode(f, seq_++));
    return IoStatus::kOk;
  }
  hid::Report r{};
  std::memcpy(r.data(), data, hid::kReportSize);
  ++host_reports_;
  last_host_seq_ = h.seq;
  last_host_t_s_ = t_s_;
  Handle(r, h);
  return IoStatus::kOk;
}

void HidDeviceEmulator::Handle(const hid::Report& r, const hid::Header& h) {
  const hid::Identity& id = opt_.identity;
  auto bad_command = [&] {
    hid::Fault f;
    f.code = hid::FaultCode::kBadCommand;
    f.sample_index = next_index_;
    f.value = static_cast<float>(r[0]);
    Queue(hid::Encode(f, seq_++));
  };
  switch (h.type) {
    case hid::Type::kIdentify: Queue(hid::Encode(id, seq_++)); return;
    case hid::Type::kConfigure: {
      hid::Configure c;
      if (sampling_) return Ack(h, hid::AckResult::kBadState);
      if (!hid::Decode(r, &c).ok()) return Ack(h, hid::AckResult::kBadParameter, 6);
      if (c.sample_rate_Hz > id.max_sample_rate_Hz) return Ack(h, hid::AckResult::kBadParameter, 6);
      if (double(c.sample_rate_Hz) / c.samples_per_report > id.max_report_rate_Hz)
        return Ack(h, hid::AckResult::kBadParameter, 10);
      if (c.watchdog_ms < id.min_watchdog_ms) return Ack(h, hid::AckResult::kBadParameter, 11);
      cfg_ = c;
      if (cfg_.max_current_mA == 0 || cfg_.max_current_mA > id.max_current_mA) cfg_.max_current_mA = id.max_current_mA;
      configured_ = true;
      return Ack(h, hid::AckResult::kOk);
    }
    case hid::Type::kStart: {
      if (!configured_ || sampling_) return Ack(h, hid::AckResult::kBadState);
      RunConfig rc;
      rc.supply_V = opt_.supply_V;
      rc.sample_rate_Hz = 0.0;
      if (!valve_.Configure(rc).ok() || !valve_.Start(nullptr).ok()) return Ack(h, hid::AckResult::kBadState);
      GoSafe();
      t_s_ = last_host_t_s_ = 0.0;
      next_index_ = 0;
      sampling_ = true;
      return Ack(h, hid::AckResult::kOk);
    }
    case hid::Type::kStop:
      GoSafe();
      sampling_ = false;
      return Ack(h, hid::AckResult::kOk);
    case hid::Type::kSetPwm: {
      hid::SetPwm p;
      if (latched_) return;  // a latched fault ignores drive commands until CLEAR_FAULT
      if (!sampling_ || loop_.mode != hid::LoopMode::kHost || !hid::Decode(r, &p).ok() ||
          p.carrier_Hz < id.min_pwm_Hz || p.carrier_Hz > id.max_pwm_Hz)
        return bad_command();
      (void)valve_.Apply(SwitchCommand{SwitchCommand::Mode::kPwm, 0, p.duty / 65535.0, p.carrier_Hz, p.restart_carrier});
      pwm_running_ = p.duty > 0;
      return;
    }
    case hid::Type::kSetGate: {
      hid::SetGate g;
      if (latched_) return;
      if (!sampling_ || loop_.mode != hid::LoopMode::kHost || !hid::Decode(r, &g).ok() ||
          (g.level < 0 && !(id.flags & hid::kCapHBridge)))
        return bad_command();
      (void)valve_.Apply(SwitchCommand::Gate(g.level));
      pwm_running_ = false;
      return;
    }
    case hid::Type::kSetLoop: {
      hid::SetLoop l;
      if (!hid::Decode(r, &l).ok()) return Ack(h, hid::AckResult::kBadParameter, 6);
      if (latched_ || !sampling_) return Ack(h, hid::AckResult::kBadState);
      const std::uint8_t need = l.mode == hid::LoopMode::kOpenLoop     ? hid::kCapLoopOpen
                                : l.mode == hid::LoopMode::kHysteresis ? hid::kCapLoopHysteresis
                                : l.mode == hid::LoopMode::kPi         ? hid::kCapLoopPi
                                                                       : 0;
      if (need != 0 && !(id.flags & need)) return Ack(h, hid::AckResult::kUnsupported);
      if (l.loop_rate_Hz > id.max_inner_loop_Hz) return Ack(h, hid::AckResult::kBadParameter, 27);
      if (l.mode != hid::LoopMode::kHost && l.mode != hid::LoopMode::kHysteresis &&
          (l.carrier_Hz < id.min_pwm_Hz || l.carrier_Hz > id.max_pwm_Hz))
        return Ack(h, hid::AckResult::kBadParameter, 23);
      GoSafe();
      loop_ = l;
      integral_V_ = 0.0;
      hyst_gate_ = 0;
      next_loop_t_s_ = t_s_;
      if (l.mode == hid::LoopMode::kOpenLoop) {
        (void)valve_.Apply(SwitchCommand::Pwm(std::clamp<double>(l.setpoint, 0.0, 1.0), l.carrier_Hz));
        pwm_running_ = true;
      }
      return Ack(h, hid::AckResult::kOk);
    }
    case hid::Type::kHeartbeat: return;
    case hid::Type::kSafe: GoSafe(); return;
    case hid::Type::kClearFault:
      latched_ = false;
      return Ack(h, hid::AckResult::kOk);
    default: return;
  }
}

void HidDeviceEmulator::AdvanceValve(double t_s) {
  if (t_s <= t_s_) return;
  Measurement m;
  (void)valve_.AdvanceTo(t_s, &m);
  i_A_ = m.current_A;
  t_s_ = t_s;
}

void HidDeviceEmulator::LoopTick() {
  const double i = i_A_;
  switch (loop_.mode) {
    case hid::LoopMode::kHysteresis: {
      if (i < loop_.setpoint - 0.5 * loop_.band_A) hyst_gate_ = 1;
      if (i > loop_.setpoint + 0.5 * loop_.band_A) hyst_gate_ = 0;
      (void)valve_.Apply(SwitchCommand::Gate(hyst_gate_));
      pwm_running_ = hyst_gate_ != 0;
      break;
    }
    case hid::LoopMode::kPi: {
      const double e = loop_.setpoint - i;
      integral_V_ = std::clamp(integral_V_ + loop_.ki_V_per_A_s * e / loop_.loop_rate_Hz, 0.0, opt_.supply_V);
      const double v = loop_.kp_V_per_A * e + integral_V_;
      (void)valve_.Apply(SwitchCommand::Pwm(std::clamp(v / opt_.supply_V, 0.0, 1.0), loop_.carrier_Hz));
      pwm_running_ = true;
      break;
    }
    default: break;
  }
}

void HidDeviceEmulator::ProduceReport() {
  hid::Samples s;
  s.first_index = next_index_;
  s.count = cfg_.samples_per_report;
  s.last_host_seq = last_host_seq_;
  const double lsb_A = opt_.identity.current_lsb_nA * 1e-9;
  const double watchdog_s = cfg_.watchdog_ms * 1e-3;
  const std::size_t faults_before = out_.size();
  for (int k = 0; k < s.count; ++k) {
    const double ts = static_cast<double>(next_index_) / cfg_.sample_rate_Hz;
    if (loop_.mode == hid::LoopMode::kHysteresis || loop_.mode == hid::LoopMode::kPi) {
      while (next_loop_t_s_ <= ts + 1e-12) {
        AdvanceValve(next_loop_t_s_);
        LoopTick();
        next_loop_t_s_ += 1.0 / loop_.loop_rate_Hz;
      }
    }
    AdvanceValve(ts);
    if (!latched_ && ts - last_host_t_s_ > watchdog_s) Trip(hid::FaultCode::kWatchdog, float((ts - last_host_t_s_) * 1e3));
    if (!latched_ && std::abs(i_A_) > cfg_.max_current_mA * 1e-3) Trip(hid::FaultCode::kOvercurrent, float(i_A_));
    s.current[k] = static_cast<std::int16_t>(std::clamp(std::lround(i_A_ / lsb_A), -32768L, 32767L));
    if (valve_.simulator().gate() == 1) s.gate_bits |= 1u << k;
    ++next_index_;
  }
  if (latched_) s.flags |= hid::kSamplesSafe;
  // The samples go out before any fault raised while taking them (a fault names the sample it tripped at).
  std::deque<hid::Report> faults(out_.begin() + static_cast<long>(faults_before), out_.end());
  out_.erase(out_.begin() + static_cast<long>(faults_before), out_.end());
  // Re-number: samples first, then the faults, in sending order.
  seq_ -= static_cast<std::uint32_t>(faults.size());
  Queue(hid::Encode(s, seq_++));
  for (auto& f : faults) {
    f[2] = static_cast<std::uint8_t>(seq_);
    f[3] = static_cast<std::uint8_t>(seq_ >> 8);
    f[4] = static_cast<std::uint8_t>(seq_ >> 16);
    f[5] = static_cast<std::uint8_t>(seq_ >> 24);
    f[hid::kReportSize - 1] = hid::Crc8(f.data(), hid::kReportSize - 1);
    ++seq_;
    Queue(f);
  }
}

IoStatus HidDeviceEmulator::HostRead(std::uint8_t* buf, std::size_t capacity, std::size_t* received) {
  *received = 0;
  if (!plugged_) return IoStatus::kDisconnected;
  if (out_.empty()) {
    if (!sampling_) return IoStatus::kTimeout;
    ProduceReport();
  }
  const hid::Report r = out_.front();
  out_.pop_front();
  const std::size_t n = std::min(capacity, r.size());
  std::memcpy(buf, r.data(), n);
  *received = n;
  return IoStatus::kOk;
}

void HidDeviceEmulator::RunFor(double seconds) {
  if (!plugged_ || !sampling_) return;
  const double until = t_s_ + seconds;
  while (t_s_ < until) ProduceReport();
}

}  // namespace vb::hw::testing
