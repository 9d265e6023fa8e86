#include "hw/hid/hid_protocol.h"

#include <cmath>
#include <cstring>

namespace vb::hw::hid {

namespace {

void Put16(Report* r, int at, std::uint16_t v) {
  (*r)[at] = static_cast<std::uint8_t>(v);
  (*r)[at + 1] = static_cast<std::uint8_t>(v >> 8);
}
void Put32(Report* r, int at, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) (*r)[at + k] = static_cast<std::uint8_t>(v >> (8 * k));
}
void PutF(Report* r, int at, float f) {
  std::uint32_t v;
  std::memcpy(&v, &f, 4);
  Put32(r, at, v);
}
std::uint16_t Get16(const Report& r, int at) {
  return static_cast<std::uint16_t>(r[at] | (r[at + 1] << 8));
}
std::uint32_t Get32(const Report& r, int at) {
  std::uint32_t v = 0;
  for (int k = 0; k < 4; ++k) v |= static_cast<std::uint32_t>(r[at + k]) << (8 * k);
  return v;
}
float GetF(const Report& r, int at) {
  const std::uint32_t v = Get32(r, at);
  float f;
  std::memcpy(&f, &v, 4);
  return f;
}

Report Begin(Type t, std::uint32_t seq) {
  Report r{};
  r[0] = static_cast<std::uint8_t>(t);
  r[1] = kProtocolVersion;
  Put32(&r, 2, seq);
  return r;
}
Report Seal(Report r) {
  r[kReportSize - 1] = Crc8(r.data(), kReportSize - 1);
  return r;
}
Status Bad(const char* field, const std::string& what) {
  return Status::InvalidArgument(std::string(field) + ": " + what);
}
bool Finite(float f) { return std::isfinite(f); }

}  // namespace

const char* TypeName(Type t) {
  switch (t) {
    case Type::kIdentify: return "IDENTIFY";
    case Type::kConfigure: return "CONFIGURE";
    case Type::kStart: return "START";
    case Type::kStop: return "STOP";
    case Type::kSetPwm: return "SET_PWM";
    case Type::kSetGate: return "SET_GATE";
    case Type::kSetLoop: return "SET_LOOP";
    case Type::kHeartbeat: return "HEARTBEAT";
    case Type::kSafe: return "SAFE";
    case Type::kClearFault: return "CLEAR_FAULT";
    case Type::kIdentity: return "IDENTITY";
    case Type::kAck: return "ACK";
    case Type::kSamples: return "SAMPLES";
    case Type::kFault: return "FAULT";
  }
  return "UNKNOWN";
}

const char* FaultName(FaultCode c) {
  switch (c) {
    case FaultCode::kWatchdog: return "watchdog";
    case FaultCode::kOvercurrent: return "overcurrent";
    case FaultCode::kSupplyLow: return "supply low";
    case FaultCode::kOvertemperature: return "driver overtemperature";
    case FaultCode::kBadReport: return "bad report";
    case FaultCode::kBadCommand: return "bad command";
    case FaultCode::kOverrun: return "sample overrun";
  }
  return "unknown fault";
}

std::uint8_t Crc8(const std::uint8_t* data, std::size_t size) {
  std::uint8_t crc = 0;
  for (std::size_t k = 0; k < size; ++k) {
    crc ^= data[k];
    for (int b = 0; b < 8; ++b) crc = static_cast<std::uint8_t>((crc & 0x80) ? (crc << 1) ^ 0x07 : crc << 1);
  }
  return crc;
}

Status ParseHeader(const std::uint8_t* data, std::size_t size, Header* h) {
  if (size != kReportSize)
    return Status::DataLoss("short report: " + std::to_string(size) + " of " + std::to_string(kReportSize) +
                            " bytes");
  const std::uint8_t crc = Crc8(data, kReportSize - 1);
  if (crc != data[kReportSize - 1])
    return Status::DataLoss("corrupt report: CRC-8 is " + std::to_string(data[kReportSize - 1]) + ", computed " +
                            std::to_string(crc));
  if (data[1] != kProtocolVersion)
    return Status::DataLoss("report: protocol version " + std::to_string(data[1]) + ", expected " +
                            std::to_string(kProtocolVersion));
  const std::uint8_t t = data[0];
  const bool known = (t >= 0x01 && t <= 0x0A) || (t >= 0x81 && t <= 0x84);
  if (!known) return Status::DataLoss("report: unknown type 0x" + std::to_string(t));
  h->type = static_cast<Type>(t);
  h->seq = static_cast<std::uint32_t>(data[2]) | (static_cast<std::uint32_t>(data[3]) << 8) |
           (static_cast<std::uint32_t>(data[4]) << 16) | (static_cast<std::uint32_t>(data[5]) << 24);
  return Status::Ok();
}

Report Encode(Type t, std::uint32_t seq) { return Seal(Begin(t, seq)); }

Report Encode(const Identity& m, std::uint32_t seq) {
  Report r = Begin(Type::kIdentity, seq);
  Put16(&r, 6, m.firmware_version);
  r[8] = m.flags;
  r[9] = m.current_channels;
  Put32(&r, 10, m.max_supply_mV);
  PutF(&r, 14, m.min_pwm_Hz);
  PutF(&r, 18, m.max_pwm_Hz);
  Put32(&r, 22, m.max_sample_rate_Hz);
  Put16(&r, 26, m.max_report_rate_Hz);
  Put32(&r, 28, m.max_inner_loop_Hz);
  Put32(&r, 32, m.current_lsb_nA);
  Put32(&r, 36, m.max_current_mA);
  std::memcpy(&r[40], m.serial, 16);
  Put16(&r, 56, m.min_watchdog_ms);
  return Seal(r);
}

Status Decode(const Report& r, Identity* m) {
  m->firmware_version = Get16(r, 6);
  m->flags = r[8];
  m->current_channels = r[9];
  m->max_supply_mV = Get32(r, 10);
  m->min_pwm_Hz = GetF(r, 14);
  m->max_pwm_Hz = GetF(r, 18);
  m->max_sample_rate_Hz = Get32(r, 22);
  m->max_report_rate_Hz = Get16(r, 26);
  m->max_inner_loop_Hz = Get32(r, 28);
  m->current_lsb_nA = Get32(r, 32);
  m->max_current_mA = Get32(r, 36);
  std::memcpy(m->serial, &r[40], 16);
  m->min_watchdog_ms = Get16(r, 56);
  if (m->current_channels == 0) return Bad("identity.current_channels", "must be >= 1");
  if (m->max_supply_mV == 0) return Bad("identity.max_supply_mV", "must be > 0");
  if (!Finite(m->min_pwm_Hz) || !Finite(m->max_pwm_Hz) || !(m->min_pwm_Hz > 0.0f) || m->max_pwm_Hz < m->min_pwm_Hz)
    return Bad("identity.min_pwm_Hz/max_pwm_Hz", "need 0 < min <= max");
  if (m->max_sample_rate_Hz == 0) return Bad("identity.max_sample_rate_Hz", "must be > 0");
  if (m->max_report_rate_Hz == 0) return Bad("identity.max_report_rate_Hz", "must be > 0");
  if (m->current_lsb_nA == 0) return Bad("identity.current_lsb_nA", "must be > 0");
  if (m->max_current_mA == 0) return Bad("identity.max_current_mA", "must be > 0");
  return Status::Ok();
}

Report Encode(const Configure& m, std::uint32_t seq) {
  Report r = Begin(Type::kConfigure, seq);
  Put32(&r, 6, m.sample_rate_Hz);
  r[10] = m.samples_per_report;
  Put16(&r, 11, m.watchdog_ms);
  Put32(&r, 13, m.max_current_mA);
  return Seal(r);
}

Status Decode(const Report& r, Configure* m) {
  m->sample_rate_Hz = Get32(r, 6);
  m->samples_per_report = r[10];
  m->watchdog_ms = Get16(r, 11);
  m->max_current_mA = Get32(r, 13);
  if (m->sample_rate_Hz == 0) return Bad("configure.sample_rate_Hz", "must be > 0");
  if (m->samples_per_report == 0 || m->samples_per_report > kMaxSamplesPerReport)
    return Bad("configure.samples_per_report", "must be in 1..20, got " + std::to_string(m->samples_per_report));
  if (m->watchdog_ms == 0) return Bad("configure.watchdog_ms", "must be > 0 (the watchdog cannot be disabled)");
  return Status::Ok();
}

Report Encode(const SetPwm& m, std::uint32_t seq) {
  Report r = Begin(Type::kSetPwm, seq);
  PutF(&r, 6, m.carrier_Hz);
  Put16(&r, 10, m.duty);
  r[12] = m.restart_carrier ? 1 : 0;
  return Seal(r);
}

Status Decode(const Report& r, SetPwm* m) {
  m->carrier_Hz = GetF(r, 6);
  m->duty = Get16(r, 10);
  m->restart_carrier = (r[12] & 1) != 0;
  if (!Finite(m->carrier_Hz) || !(m->carrier_Hz > 0.0f)) return Bad("set_pwm.carrier_Hz", "must be > 0");
  return Status::Ok();
}

Report Encode(const SetGate& m, std::uint32_t seq) {
  Report r = Begin(Type::kSetGate, seq);
  r[6] = static_cast<std::uint8_t>(m.level);
  return Seal(r);
}

Status Decode(const Report& r, SetGate* m) {
  m->level = static_cast<std::int8_t>(r[6]);
  if (m->level < -1 || m->level > 1) return Bad("set_gate.level", "must be -1, 0 or 1");
  return Status::Ok();
}

Report Encode(const SetLoop& m, std::uint32_t seq) {
  Report r = Begin(Type::kSetLoop, seq);
  r[6] = static_cast<std::uint8_t>(m.mode);
  PutF(&r, 7, m.setpoint);
  PutF(&r, 11, m.band_A);
  PutF(&r, 15, m.kp_V_per_A);
  PutF(&r, 19, m.ki_V_per_A_s);
  PutF(&r, 23, m.carrier_Hz);
  Put32(&r, 27, m.loop_rate_Hz);
  return Seal(r);
}

Status Decode(const Report& r, SetLoop* m) {
  if (r[6] > 3) return Bad("set_loop.mode", "must be 0..3, got " + std::to_string(r[6]));
  m->mode = static_cast<LoopMode>(r[6]);
  m->setpoint = GetF(r, 7);
  m->band_A = GetF(r, 11);
  m->kp_V_per_A = GetF(r, 15);
  m->ki_V_per_A_s = GetF(r, 19);
  m->carrier_Hz = GetF(r, 23);
  m->loop_rate_Hz = Get32(r, 27);
  if (!Finite(m->setpoint) || !Finite(m->band_A) || !Finite(m->kp_V_per_A) || !Finite(m->ki_V_per_A_s) ||
      !Finite(m->carrier_Hz))
    return Bad("set_loop", "parameters must be finite");
  if (m->mode != LoopMode::kHost && m->loop_rate_Hz == 0) return Bad("set_loop.loop_rate_Hz", "must be > 0");
  return Status::Ok();
}

Report Encode(const Ack& m, std::uint32_t seq) {
  Report r = Begin(Type::kAck, seq);
  r[6] = static_cast<std::uint8_t>(m.acked_type);
  Put32(&r, 7, m.acked_seq);
  r[11] = static_cast<std::uint8_t>(m.result);
  r[12] = m.field_offset;
  return Seal(r);
}

Status Decode(const Report& r, Ack* m) {
  m->acked_type = static_cast<Type>(r[6]);
  m->acked_seq = Get32(r, 7);
  if (r[11] > 3) return Bad("ack.result", "must be 0..3, got " + std::to_string(r[11]));
  m->result = static_cast<AckResult>(r[11]);
  m->field_offset = r[12];
  return Status::Ok();
}

Report Encode(const Samples& m, std::uint32_t seq) {
  Report r = Begin(Type::kSamples, seq);
  Put32(&r, 6, m.first_index);
  r[10] = m.count;
  r[11] = m.flags;
  Put32(&r, 12, m.gate_bits);
  Put32(&r, 16, m.last_host_seq);
  for (int k = 0; k < kMaxSamplesPerReport; ++k) Put16(&r, 20 + 2 * k, static_cast<std::uint16_t>(m.current[k]));
  return Seal(r);
}

Status Decode(const Report& r, Samples* m) {
  m->first_index = Get32(r, 6);
  m->count = r[10];
  m->flags = r[11];
  m->gate_bits = Get32(r, 12);
  m->last_host_seq = Get32(r, 16);
  if (m->count == 0 || m->count > kMaxSamplesPerReport)
    return Bad("samples.count", "must be in 1..20, got " + std::to_string(m->count));
  for (int k = 0; k < kMaxSamplesPerReport; ++k) m->current[k] = static_cast<std::int16_t>(Get16(r, 20 + 2 * k));
  return Status::Ok();
}

Report Encode(const Fault& m, std::uint32_t seq) {
  Report r = Begin(Type::kFault, seq);
  r[6] = static_cast<std::uint8_t>(m.code);
  Put32(&r, 7, m.sample_index);
  PutF(&r, 11, m.value);
  return Seal(r);
}

Status Decode(const Report& r, Fault* m) {
  if (r[6] < 1 || r[6] > 7) return Bad("fault.code", "unknown code " + std::to_string(r[6]));
  m->code = static_cast<FaultCode>(r[6]);
  m->sample_index = Get32(r, 7);
  m->value = GetF(r, 11);
  return Status::Ok();
}

std::string SerialOf(const Identity& id) {
  std::string s(id.serial, strnlen(id.serial, sizeof(id.serial)));
  return s;
}

}  // namespace vb::hw::hid
