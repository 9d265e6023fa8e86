#include "common/format.h"
#include "hw/device_bench.h"
#include "hw/hid/hid_bench.h"

#include <algorithm>
#include <cmath>

namespace vb::hw {

HidBench::HidBench(std::unique_ptr<Transport> transport, HidBenchOptions options)
    : transport_(std::move(transport)), opt_(std::move(options)) {}

StatusOr<std::unique_ptr<HidBench>> HidBench::Open(std::unique_ptr<Transport> transport, HidBenchOptions options) {
  if (transport == nullptr) return Status::InvalidArgument("transport: none given");
  if (!(options.watchdog_s > 0.0) || options.watchdog_s > 60.0)
    return Status::InvalidArgument("watchdog_s: must be in (0, 60] s, got " + FormatNumber(options.watchdog_s));
  std::unique_ptr<HidBench> b(new HidBench(std::move(transport), std::move(options)));
  VB_RETURN_IF_ERROR(b->Identify());
  return b;
}

Status HidBench::Identify() {
  have_dev_seq_ = false;
  // Anything still queued from before (a previous session's samples) is drained first.
  hid::Report r;
  std::size_t got = 0;
  for (int k = 0; k < 1000; ++k)
    if (transport_->Read(0, r.data(), r.size(), &got, 0) != IoStatus::kOk) break;
  // A device that was streaming keeps its state; SAFE + STOP make it quiet before it identifies.
  (void)Send(hid::Encode(hid::Type::kSafe, ++host_seq_));
  VB_RETURN_IF_ERROR(Send(hid::Encode(hid::Type::kIdentify, ++host_seq_)));
  for (int k = 0; k < 1000; ++k) {
    hid::Header h;
    const IoStatus io = transport_->Read(0, r.data(), r.size(), &got, opt_.read_timeout_ms);
    if (io != IoStatus::kOk) return TransportError(io, "identify", *transport_, opt_.read_timeout_ms);
    VB_RETURN_IF_ERROR(hid::ParseHeader(r.data(), got, &h).WithContext("identify"));
    if (h.type != hid::Type::kIdentity) continue;  // leftovers of a stream
    VB_RETURN_IF_ERROR(hid::Decode(r, &id_).WithContext(transport_->Describe()));
    have_dev_seq_ = true;
    next_dev_seq_ = h.seq + 1;
    break;
  }
  if (!have_dev_seq_) return Status::DataLoss("identify: no IDENTITY report from " + transport_->Describe());
  caps_ = Capabilities{};
  caps_.kind = "hid";
  caps_.driver = (id_.flags & hid::kCapHBridge) ? "h_bridge" : opt_.driver;
  caps_.max_supply_V = id_.max_supply_mV / 1000.0;
  if (opt_.max_supply_V > 0.0) caps_.max_supply_V = std::min(caps_.max_supply_V, opt_.max_supply_V);
  caps_.min_carrier_Hz = id_.min_pwm_Hz;
  caps_.max_carrier_Hz = id_.max_pwm_Hz;
  caps_.max_sample_rate_Hz =
      std::min<double>(id_.max_sample_rate_Hz, double(id_.max_report_rate_Hz) * hid::kMaxSamplesPerReport);
  caps_.max_control_rate_Hz = id_.max_report_rate_Hz;  // one host decision per report at best
  caps_.measures_position = caps_.measures_velocity = false;
  caps_.max_current_A = id_.max_current_mA / 1000.0;
  if (opt_.max_current_A > 0.0) caps_.max_current_A = std::min(caps_.max_current_A, opt_.max_current_A);
  caps_.serial = hid::SerialOf(id_);
  caps_.max_device_loop_Hz = id_.max_inner_loop_Hz;
  if (id_.flags & hid::kCapLoopOpen) caps_.device_loops.push_back("open_loop");
  if (id_.flags & hid::kCapLoopHysteresis) caps_.device_loops.push_back("hysteresis");
  if (id_.flags & hid::kCapLoopPi) caps_.device_loops.push_back("pi");
  if (opt_.watchdog_s * 1000.0 < id_.min_watchdog_ms)
    return Status::InvalidArgument("watchdog_s: " + FormatNumber(opt_.watchdog_s) + " s is below the device's minimum of " +
                                   std::to_string(id_.min_watchdog_ms) + " ms");
  return Status::Ok();
}

Status HidBench::Send(const hid::Report& r) {
  const IoStatus io = transport_->Write(0, r.data(), r.size(), opt_.write_timeout_ms);
  if (io == IoStatus::kDisconnected) need_reopen_ = true;
  if (io != IoStatus::kOk) return TransportError(io, "write", *transport_, opt_.write_timeout_ms);
  last_write_index_ = next_index_;
  return Status::Ok();
}

Status HidBench::Receive(hid::Report* r, hid::Header* h) {
  std::size_t got = 0;
  const IoStatus io = transport_->Read(0, r->data(), r->size(), &got, opt_.read_timeout_ms);
  if (io == IoStatus::kDisconnected) need_reopen_ = true;
  if (io != IoStatus::kOk) return TransportError(io, "read", *transport_, opt_.read_timeout_ms);
  VB_RETURN_IF_ERROR(hid::ParseHeader(r->data(), got, h).WithContext(transport_->Describe()));
  if (have_dev_seq_ && h->seq != next_dev_seq_) {
    const auto ahead = static_cast<std::int32_t>(h->seq - next_dev_seq_);
    if (ahead < 0)
      return Status::DataLoss(transport_->Describe() + ": stale report (sequence " + std::to_string(h->seq) +
                              ", expected " + std::to_string(next_dev_seq_) + ")");
    return Status::DataLoss(transport_->Describe() + ": lost " + std::to_string(ahead) + " report(s) (sequence " +
                            std::to_string(h->seq) + ", expected " + std::to_string(next_dev_seq_) + ")");
  }
  have_dev_seq_ = true;
  next_dev_seq_ = h->seq + 1;
  return Status::Ok();
}

Status HidBench::Lost(Status st) {
  SafeState();
  return st;
}

Status HidBench::Configure(const RunConfig& config) {
  if (running_) return Status::FailedPrecondition("bench " + opt_.name + " is running");
  if (need_reopen_) {
    VB_RETURN_IF_ERROR(Reconnect(*transport_, opt_.reopen_attempts, [this] { return Identify(); }, opt_.name));
    need_reopen_ = false;
  }
  VB_RETURN_IF_ERROR(CheckSupply(config.supply_V, caps_.max_supply_V, opt_.name));
  const double rate = config.sample_rate_Hz > 0.0 ? config.sample_rate_Hz : opt_.default_sample_rate_Hz;
  if (rate > caps_.max_sample_rate_Hz || rate != std::floor(rate))
    return Status::FailedPrecondition("sample_rate_Hz: " + FormatNumber(rate) + " Hz; bench " + opt_.name +
                                      " samples at whole rates up to " + FormatNumber(caps_.max_sample_rate_Hz) + " Hz");
  per_report_ = std::clamp(static_cast<int>(std::ceil(rate / id_.max_report_rate_Hz)), 1, hid::kMaxSamplesPerReport);
  hid::Configure c;
  c.sample_rate_Hz = static_cast<std::uint32_t>(rate);
  c.samples_per_report = static_cast<std::uint8_t>(per_report_);
  c.watchdog_ms = static_cast<std::uint16_t>(std::clamp(std::lround(opt_.watchdog_s * 1000.0), 1L, 65535L));
  c.max_current_mA = static_cast<std::uint32_t>(std::lround(caps_.max_current_A * 1000.0));
  VB_RETURN_IF_ERROR(Command(hid::Encode(c, ++host_seq_), hid::Type::kConfigure));
  rate_Hz_ = rate;
  config_ = config;
  configured_ = true;
  return Status::Ok();
}

Status HidBench::Command(const hid::Report& out, hid::Type type) {
  const std::uint32_t seq = host_seq_;
  Status st = Send(out);
  if (!st.ok()) return Lost(st);
  for (int k = 0; k < 10000; ++k) {
    hid::Report r;
    hid::Header h;
    st = Receive(&r, &h);
    if (!st.ok()) return Lost(st.WithContext(std::string("waiting for the ACK of ") + hid::TypeName(type)));
    if (h.type != hid::Type::kAck) {
      st = Handle(r, h);
      if (!st.ok()) return Lost(st);
      continue;
    }
    hid::Ack a;
    VB_RETURN_IF_ERROR(hid::Decode(r, &a));
    if (a.acked_seq != seq) continue;  // the answer to an earlier command
    if (a.result == hid::AckResult::kOk) return Status::Ok();
    std::string why = a.result == hid::AckResult::kBadParameter ? "a bad parameter at byte " + std::to_string(a.field_offset)
                      : a.result == hid::AckResult::kBadState   ? "the wrong state"
                                                                : "an unsupported request";
    return Status::FailedPrecondition(std::string(hid::TypeName(type)) + ": the device " + transport_->Describe() +
                                      " refused it (" + why + ")");
  }
  return Lost(Status::DataLoss(std::string(hid::TypeName(type)) + ": no ACK from " + transport_->Describe()));
}

Status HidBench::Start(SampleSink* sink) {
  if (!configured_) return Status::FailedPrecondition("bench " + opt_.name + ": Configure() first");
  sink_ = sink;
  fault_ = Status::Ok();
  have_cmd_ = false;
  device_loop_ = false;
  stats_ = LoopStats{};
  next_index_ = 0;
  emitted_ = -1;
  target_ = 0;
  VB_RETURN_IF_ERROR(Command(hid::Encode(hid::Type::kClearFault, ++host_seq_), hid::Type::kClearFault));
  VB_RETURN_IF_ERROR(Command(hid::Encode(hid::Type::kStart, ++host_seq_), hid::Type::kStart));
  next_index_ = 0;
  last_write_index_ = 0;
  running_ = true;
  return Status::Ok();
}

void HidBench::Emit(std::uint32_t index) {
  const Sample& s = ring_[index % kRing];
  emitted_ = index;
  if (sink_ == nullptr) return;
  sink_->OnSample(CurrentOnlySample(index / rate_Hz_, s.gate, s.i_A));
}

Status HidBench::Handle(const hid::Report& r, const hid::Header& h) {
  if (h.type == hid::Type::kFault) {
    hid::Fault f;
    VB_RETURN_IF_ERROR(hid::Decode(r, &f));
    std::string what = std::string("device fault on ") + transport_->Describe() + ": " + hid::FaultName(f.code);
    switch (f.code) {
      case hid::FaultCode::kWatchdog: what += " (no host report for " + FormatNumber(f.value) + " ms)"; break;
      case hid::FaultCode::kOvercurrent: what += " (" + FormatNumber(f.value) + " A)"; break;
      case hid::FaultCode::kSupplyLow: what += " (" + FormatNumber(f.value) + " V)"; break;
      default: break;
    }
    if (rate_Hz_ > 0.0) what += " at t = " + FormatNumber(f.sample_index / rate_Hz_) + " s; the device went to its safe state";
    fault_ = Status::Aborted(what);
    return fault_;
  }
  if (h.type != hid::Type::kSamples) return Status::Ok();  // late ACKs, identities: nothing to do
  if (!running_) return Status::Ok();                       // samples after STOP are dropped
  hid::Samples s;
  VB_RETURN_IF_ERROR(hid::Decode(r, &s).WithContext(transport_->Describe()));
  if (s.first_index != next_index_)
    return Status::DataLoss(transport_->Describe() + ": sample gap (report starts at sample " +
                            std::to_string(s.first_index) + ", expected " + std::to_string(next_index_) + ")");
  const double lsb_A = id_.current_lsb_nA * 1e-9;
  for (int k = 0; k < s.count; ++k) {
    const std::uint32_t idx = s.first_index + static_cast<std::uint32_t>(k);
    ring_[idx % kRing] = Sample{s.current[k] * lsb_A, static_cast<std::int8_t>((s.gate_bits >> k) & 1u)};
    if (static_cast<std::int64_t>(idx) <= target_) Emit(idx);
  }
  next_index_ = s.first_index + s.count;
  return Status::Ok();
}

Status HidBench::AdvanceTo(double t_s, Measurement* m) {
  if (!running_) return Status::FailedPrecondition("bench " + opt_.name + " is not running");
  if (!fault_.ok()) return fault_;
  target_ = static_cast<std::int64_t>(std::floor(t_s * rate_Hz_ + 1e-6));
  // Samples already here (the tail of the last report) first.
  while (emitted_ < target_ && emitted_ + 1 < static_cast<std::int64_t>(next_index_))
    Emit(static_cast<std::uint32_t>(emitted_ + 1));
  while (static_cast<std::int64_t>(next_index_) <= target_) {
    hid::Report r;
    hid::Header h;
    Status st = Receive(&r, &h);
    if (st.ok()) st = Handle(r, h);
    if (!st.ok()) return Lost(st);
    if ((next_index_ - last_write_index_) >= opt_.watchdog_s * 0.25 * rate_Hz_) {
      st = Send(hid::Encode(hid::Type::kHeartbeat, ++host_seq_));
      if (!st.ok()) return Lost(st);
    }
  }
  ++stats_.ticks;
  if (m != nullptr)
    FillCurrentOnlyMeasurement(t_s, ring_[static_cast<std::size_t>(target_) % kRing].i_A, config_.supply_V, m);
  return Status::Ok();
}

Status HidBench::Apply(const SwitchCommand& c) {
  if (!running_) return Status::FailedPrecondition("bench " + opt_.name + " is not running");
  if (!fault_.ok()) return fault_;
  if (device_loop_) return Status::FailedPrecondition("bench " + opt_.name + ": the on-device loop has the gate");
  if (have_cmd_ && c.mode == last_cmd_.mode && !c.restart_carrier &&
      (c.mode == SwitchCommand::Mode::kGate ? c.gate == last_cmd_.gate
                                            : c.duty == last_cmd_.duty && c.carrier_Hz == last_cmd_.carrier_Hz))
    return Status::Ok();  // nothing changed: nothing to send
  hid::Report r;
  if (c.mode == SwitchCommand::Mode::kGate) {
    if (c.gate < -1 || c.gate > 1) return Status::InvalidArgument("gate: must be -1, 0 or 1");
    if (c.gate == -1 && caps_.driver != "h_bridge")
      return Status::FailedPrecondition("gate -1 needs an H-bridge; bench " + opt_.name + " has " + caps_.driver);
    r = hid::Encode(hid::SetGate{c.gate}, ++host_seq_);
  } else {
    if (!(c.carrier_Hz >= caps_.min_carrier_Hz && c.carrier_Hz <= caps_.max_carrier_Hz))
      return Status::FailedPrecondition("carrier_Hz: " + FormatNumber(c.carrier_Hz) + " Hz is outside the PWM range [" +
                                        FormatNumber(caps_.min_carrier_Hz) + ", " + FormatNumber(caps_.max_carrier_Hz) +
                                        "] of bench " + opt_.name);
    hid::SetPwm p;
    p.carrier_Hz = static_cast<float>(c.carrier_Hz);
    p.duty = static_cast<std::uint16_t>(std::lround(std::clamp(c.duty, 0.0, 1.0) * 65535.0));
    p.restart_carrier = c.restart_carrier;
    r = hid::Encode(p, ++host_seq_);
  }
  Status st = Send(r);
  if (!st.ok()) return Lost(st);
  last_cmd_ = c;
  have_cmd_ = true;
  return Status::Ok();
}

Status HidBench::SetDeviceLoop(const hid::SetLoop& loop) {
  if (!running_) return Status::FailedPrecondition("bench " + opt_.name + " is not running");
  const std::uint8_t need = loop.mode == hid::LoopMode::kOpenLoop     ? hid::kCapLoopOpen
                            : loop.mode == hid::LoopMode::kHysteresis ? hid::kCapLoopHysteresis
                            : loop.mode == hid::LoopMode::kPi         ? hid::kCapLoopPi
                                                                      : 0;
  if (need != 0 && !(id_.flags & need))
    return Status::FailedPrecondition("bench " + opt_.name + ": the firmware does not run this loop on-device");
  if (loop.loop_rate_Hz > id_.max_inner_loop_Hz)
    return Status::FailedPrecondition("set_loop.loop_rate_Hz: " + std::to_string(loop.loop_rate_Hz) +
                                      " Hz exceeds the device's " + std::to_string(id_.max_inner_loop_Hz) + " Hz");
  VB_RETURN_IF_ERROR(Command(hid::Encode(loop, ++host_seq_), hid::Type::kSetLoop));
  device_loop_ = loop.mode != hid::LoopMode::kHost;
  have_cmd_ = false;
  return Status::Ok();
}

Status HidBench::Stop() {
  if (!running_) return Status::Ok();
  running_ = false;
  Status st = Command(hid::Encode(hid::Type::kStop, ++host_seq_), hid::Type::kStop);
  if (!st.ok()) SafeState();
  return st;
}

void HidBench::SafeState() noexcept {
  // Best effort and at once: SAFE has no answer to wait for. If the bus is gone the device watchdog (or the
  // loss of USB power and the gate pull-down) does it.
  const hid::Report r = hid::Encode(hid::Type::kSafe, ++host_seq_);
  (void)transport_->Write(0, r.data(), r.size(), opt_.write_timeout_ms);
  have_cmd_ = false;
  device_loop_ = false;
}

}  // namespace vb::hw
