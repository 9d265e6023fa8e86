#include "hw/u3/u3_protocol.h"

#include <fmt/format.h>
#include <cstdio>

namespace vb::hw::u3 {

namespace {

std::string Hex(unsigned v) {
  return fmt::format("0x{:02X}", v);
}

Packet Extended(Cmd cmd, std::size_t size) {
  Packet p;
  p.Resize(size);
  p[1] = 0xF8;
  p[3] = static_cast<std::uint8_t>(cmd);
  return p;
}

}  // namespace

std::uint8_t Checksum8(const std::uint8_t* data, std::size_t size) {
  unsigned a = 0;
  for (std::size_t k = 1; k < size; ++k) a += data[k];
  unsigned q = a / 256;
  a = (a - 256 * q) + q;
  q = a / 256;
  return static_cast<std::uint8_t>((a - 256 * q) + q);
}

std::uint16_t Checksum16(const std::uint8_t* data, std::size_t size) {
  unsigned a = 0;
  for (std::size_t k = 6; k < size; ++k) a += data[k];
  return static_cast<std::uint16_t>(a);
}

void SealExtended(Packet* p) {
  if (p->size() % 2 != 0) p->Push(0);
  (*p)[2] = static_cast<std::uint8_t>((p->size() - 6) / 2);
  const std::uint16_t c16 = Checksum16(p->data(), p->size());
  (*p)[4] = static_cast<std::uint8_t>(c16);
  (*p)[5] = static_cast<std::uint8_t>(c16 >> 8);
  (*p)[0] = Checksum8(p->data(), 6);
}

Packet NormalCommand(std::uint8_t cmd) {
  Packet p;
  p.Push({0, cmd});
  p[0] = Checksum8(p.data(), p.size());
  return p;
}

Status CheckExtended(const std::uint8_t* d, std::size_t size, std::uint8_t byte1, std::uint8_t command,
                     std::size_t expected_size) {
  if (size < 6 || (expected_size > 0 && size != expected_size))
    return Status::DataLoss("short packet: " + std::to_string(size) + " of " + std::to_string(expected_size) +
                            " bytes");
  if (d[1] != byte1) return Status::DataLoss("unexpected packet: byte 1 is " + Hex(d[1]) + ", expected " + Hex(byte1));
  if (d[3] != command)
    return Status::DataLoss("unexpected packet: command " + Hex(d[3]) + ", expected " + Hex(command));
  if (d[2] != (size - 6) / 2)
    return Status::DataLoss("bad packet: byte 2 says " + std::to_string(d[2]) + " words, the packet has " +
                            std::to_string((size - 6) / 2));
  const std::uint16_t c16 = Checksum16(d, size);
  if ((d[4] | (d[5] << 8)) != c16)
    return Status::DataLoss("bad Checksum16: packet says " + std::to_string(d[4] | (d[5] << 8)) + ", computed " +
                            std::to_string(c16));
  const std::uint8_t c8 = Checksum8(d, 6);
  if (d[0] != c8)
    return Status::DataLoss("bad Checksum8: packet says " + std::to_string(d[0]) + ", computed " + std::to_string(c8));
  return Status::Ok();
}

Status CheckNormal(const std::uint8_t* d, std::size_t size, std::uint8_t response_byte) {
  if (size != 4) return Status::DataLoss("short packet: " + std::to_string(size) + " of 4 bytes");
  if (d[1] != response_byte)
    return Status::DataLoss("unexpected packet: byte 1 is " + Hex(d[1]) + ", expected " + Hex(response_byte));
  if (d[0] != Checksum8(d, size))
    return Status::DataLoss("bad Checksum8: packet says " + std::to_string(d[0]) + ", computed " +
                            std::to_string(Checksum8(d, size)));
  if (d[2] != 0) return Status::FailedPrecondition("device errorcode " + ErrorcodeName(d[2]));
  return Status::Ok();
}

Packet EncodeConfigU3Read() {
  Packet p = Extended(Cmd::kConfigU3, 26);
  SealExtended(&p);
  return p;
}

Status DecodeConfigU3Response(const std::uint8_t* d, std::size_t size, DeviceInfo* info) {
  VB_RETURN_IF_ERROR(CheckExtended(d, size, 0xF8, static_cast<std::uint8_t>(Cmd::kConfigU3), kConfigU3ResponseSize)
                         .WithContext("ConfigU3"));
  if (d[6] != 0) return Status::FailedPrecondition("ConfigU3: device errorcode " + ErrorcodeName(d[6]));
  info->firmware_x100 = static_cast<std::uint16_t>(d[10] * 100 + d[9]);
  info->hardware_x100 = static_cast<std::uint16_t>(d[14] * 100 + d[13]);
  info->serial = static_cast<std::uint32_t>(d[15]) | (static_cast<std::uint32_t>(d[16]) << 8) |
                 (static_cast<std::uint32_t>(d[17]) << 16) | (static_cast<std::uint32_t>(d[18]) << 24);
  info->product_id = static_cast<std::uint16_t>(d[19] | (d[20] << 8));
  info->version_info = d[37];
  if (info->product_id != kProductId)
    return Status::FailedPrecondition("ConfigU3: product id " + std::to_string(info->product_id) +
                                      ", expected 3 (a U3)");
  return Status::Ok();
}

Packet EncodeConfigU3Response(const DeviceInfo& info, std::uint8_t fio_analog, std::uint8_t timer_counter_config) {
  Packet p = Extended(Cmd::kConfigU3, kConfigU3ResponseSize);
  p[9] = static_cast<std::uint8_t>(info.firmware_x100 % 100);
  p[10] = static_cast<std::uint8_t>(info.firmware_x100 / 100);
  p[13] = static_cast<std::uint8_t>(info.hardware_x100 % 100);
  p[14] = static_cast<std::uint8_t>(info.hardware_x100 / 100);
  for (int k = 0; k < 4; ++k) p[15 + k] = static_cast<std::uint8_t>(info.serial >> (8 * k));
  p[19] = static_cast<std::uint8_t>(info.product_id);
  p[20] = static_cast<std::uint8_t>(info.product_id >> 8);
  p[22] = timer_counter_config;
  p[23] = fio_analog;
  p[37] = info.version_info;
  SealExtended(&p);
  return p;
}

Packet Encode(const ConfigIO& c) {
  Packet p = Extended(Cmd::kConfigIO, kConfigIOSize);
  p[6] = 0x01 | 0x04;  // WriteMask: TimerCounterConfig and FIOAnalog
  p[8] = static_cast<std::uint8_t>((c.timers_enabled & 3) | ((c.pin_offset & 15) << 4));
  p[10] = c.fio_analog;
  SealExtended(&p);
  return p;
}

Status DecodeConfigIO(const std::uint8_t* d, std::size_t size, ConfigIO* c) {
  VB_RETURN_IF_ERROR(
      CheckExtended(d, size, 0xF8, static_cast<std::uint8_t>(Cmd::kConfigIO), kConfigIOSize).WithContext("ConfigIO"));
  c->timers_enabled = d[8] & 3;
  c->pin_offset = d[8] >> 4;
  c->fio_analog = d[10];
  return Status::Ok();
}

Packet EncodeConfigIOResponse(const ConfigIO& c, std::uint8_t errorcode) {
  Packet p = Extended(Cmd::kConfigIO, kConfigIOSize);
  p[6] = errorcode;
  p[8] = static_cast<std::uint8_t>((c.timers_enabled & 3) | ((c.pin_offset & 15) << 4));
  p[10] = c.fio_analog;
  SealExtended(&p);
  return p;
}

Packet Encode(const TimerClock& c) {
  Packet p = Extended(Cmd::kConfigTimerClock, kConfigTimerClockSize);
  p[8] = static_cast<std::uint8_t>(0x80 | (c.base & 7));
  p[9] = c.divisor;
  SealExtended(&p);
  return p;
}

Status DecodeTimerClock(const std::uint8_t* d, std::size_t size, TimerClock* c, bool* write) {
  VB_RETURN_IF_ERROR(CheckExtended(d, size, 0xF8, static_cast<std::uint8_t>(Cmd::kConfigTimerClock),
                                   kConfigTimerClockSize)
                         .WithContext("ConfigTimerClock"));
  if (write != nullptr) *write = (d[8] & 0x80) != 0;
  c->base = d[8] & 7;
  c->divisor = d[9];
  return Status::Ok();
}

Packet EncodeTimerClockResponse(const TimerClock& c, std::uint8_t errorcode) {
  Packet p = Extended(Cmd::kConfigTimerClock, kConfigTimerClockSize);
  p[6] = errorcode;
  p[8] = c.base & 7;
  p[9] = c.divisor;
  SealExtended(&p);
  return p;
}

double TimerClockHz(const TimerClock& c) {
  static constexpr double kBase_Hz[7] = {4e6, 12e6, 48e6, 1e6, 4e6, 12e6, 48e6};
  if (c.base > 6) return 0.0;
  const double div = c.base >= 3 ? (c.divisor == 0 ? 256.0 : c.divisor) : 1.0;
  return kBase_Hz[c.base] / div;
}

Packet Encode(const Watchdog& w) {
  Packet p = Extended(Cmd::kWatchdog, kWatchdogSize);
  p[6] = 1;  // write
  p[7] = static_cast<std::uint8_t>((w.enable && w.reset_on_timeout) ? 1 << 5 : 0);
  p[8] = static_cast<std::uint8_t>(w.timeout_s);
  p[9] = static_cast<std::uint8_t>(w.timeout_s >> 8);
  SealExtended(&p);
  return p;
}

Status DecodeWatchdog(const std::uint8_t* d, std::size_t size, Watchdog* w) {
  VB_RETURN_IF_ERROR(
      CheckExtended(d, size, 0xF8, static_cast<std::uint8_t>(Cmd::kWatchdog), kWatchdogSize).WithContext("Watchdog"));
  w->reset_on_timeout = (d[7] >> 5) & 1;
  w->enable = w->reset_on_timeout;
  w->timeout_s = static_cast<std::uint16_t>(d[8] | (d[9] << 8));
  return Status::Ok();
}

Packet EncodeWatchdogResponse(const Watchdog& w, std::uint8_t errorcode) {
  Packet p = Extended(Cmd::kWatchdog, kWatchdogSize);
  p[6] = errorcode;
  p[7] = static_cast<std::uint8_t>(w.enable && w.reset_on_timeout ? 1 << 5 : 0);
  p[8] = static_cast<std::uint8_t>(w.timeout_s);
  p[9] = static_cast<std::uint8_t>(w.timeout_s >> 8);
  SealExtended(&p);
  return p;
}

Packet FeedbackBuilder::Finish() {
  Packet out = p;
  SealExtended(&out);
  return out;
}

Status CheckFeedbackResponse(const std::uint8_t* d, std::size_t size, std::size_t expected_size) {
  VB_RETURN_IF_ERROR(CheckExtended(d, size, 0xF8, static_cast<std::uint8_t>(Cmd::kFeedback), expected_size)
                         .WithContext("Feedback"));
  if (d[6] != 0)
    return Status::FailedPrecondition("Feedback: device errorcode " + ErrorcodeName(d[6]) + " at IOType frame " +
                            std::to_string(d[7]));
  return Status::Ok();
}

Packet EncodeFeedbackResponse(std::uint8_t errorcode, std::uint8_t error_frame, const std::uint8_t* data,
                              std::size_t size) {
  Packet p = Extended(Cmd::kFeedback, 9);
  p[6] = errorcode;
  p[7] = error_frame;
  for (std::size_t k = 0; k < size; ++k) p.Push(data[k]);
  SealExtended(&p);
  return p;
}

Packet Encode(const StreamConfig& c) {
  Packet p = Extended(Cmd::kStreamConfig, 12);
  p[6] = static_cast<std::uint8_t>(c.channels.size());
  p[7] = c.samples_per_packet;
  p[9] = static_cast<std::uint8_t>((c.clock_48MHz ? 1 << 3 : 0) | (c.divide_by_256 ? 1 << 2 : 0) | (c.resolution & 3));
  p[10] = static_cast<std::uint8_t>(c.scan_interval);
  p[11] = static_cast<std::uint8_t>(c.scan_interval >> 8);
  for (const auto& [pos, neg] : c.channels) p.Push({pos, neg});
  SealExtended(&p);
  return p;
}

Status DecodeStreamConfig(const std::uint8_t* d, std::size_t size, StreamConfig* c) {
  VB_RETURN_IF_ERROR(
      CheckExtended(d, size, 0xF8, static_cast<std::uint8_t>(Cmd::kStreamConfig), 0).WithContext("StreamConfig"));
  if (size < 12 || size != 12 + 2 * static_cast<std::size_t>(d[6]))
    return Status::InvalidArgument("StreamConfig.NumChannels: " + std::to_string(d[6]) + " does not match the size");
  c->samples_per_packet = d[7];
  c->clock_48MHz = (d[9] >> 3) & 1;
  c->divide_by_256 = (d[9] >> 2) & 1;
  c->resolution = d[9] & 3;
  c->scan_interval = static_cast<std::uint16_t>(d[10] | (d[11] << 8));
  c->channels.clear();
  for (int k = 0; k < d[6]; ++k) c->channels.emplace_back(d[12 + 2 * k], d[13 + 2 * k]);
  if (c->samples_per_packet < 1 || c->samples_per_packet > 25)
    return Status::InvalidArgument("StreamConfig.SamplesPerPacket: must be 1..25, got " +
                                   std::to_string(c->samples_per_packet));
  if (c->scan_interval == 0) return Status::InvalidArgument("StreamConfig.ScanInterval: must be > 0");
  return Status::Ok();
}

Packet EncodeStreamConfigResponse(std::uint8_t errorcode) {
  Packet p = Extended(Cmd::kStreamConfig, kStreamConfigResponseSize);
  p[6] = errorcode;
  SealExtended(&p);
  return p;
}

double ScanRateHz(const StreamConfig& c) {
  const double clock = (c.clock_48MHz ? 48e6 : 4e6) / (c.divide_by_256 ? 256.0 : 1.0);
  return c.scan_interval > 0 ? clock / c.scan_interval : 0.0;
}

std::size_t StreamPacketSize(int samples_per_packet) { return 14 + 2 * static_cast<std::size_t>(samples_per_packet); }

Packet Encode(const StreamData& d) {
  Packet p;
  p.Resize(StreamPacketSize(d.count));
  p[1] = kStreamDataByte1;
  p[3] = kStreamDataCmd;
  p[10] = d.packet_number;
  p[11] = d.errorcode;
  for (int k = 0; k < d.count; ++k) {
    p[12 + 2 * k] = static_cast<std::uint8_t>(d.samples[k]);
    p[13 + 2 * k] = static_cast<std::uint8_t>(d.samples[k] >> 8);
  }
  p[12 + 2 * d.count] = d.backlog;
  SealExtended(&p);
  return p;
}

Status DecodeStreamData(const std::uint8_t* data, std::size_t size, int samples_per_packet, StreamData* d) {
  VB_RETURN_IF_ERROR(CheckExtended(data, size, kStreamDataByte1, kStreamDataCmd, StreamPacketSize(samples_per_packet))
                         .WithContext("StreamData"));
  d->packet_number = data[10];
  d->errorcode = data[11];
  d->count = samples_per_packet;
  for (int k = 0; k < samples_per_packet; ++k)
    d->samples[k] = static_cast<std::uint16_t>(data[12 + 2 * k] | (data[13 + 2 * k] << 8));
  d->backlog = data[12 + 2 * samples_per_packet];
  return Status::Ok();
}

std::string ErrorcodeName(std::uint8_t code) {
  // The numbers only: the guide's errorcode table is the reference (docs/hw-protocol.md).
  return std::to_string(code);
}

}  // namespace vb::hw::u3
