#include "hw/testing/u3_device_emulator.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "hw/u3/u3_bench.h"

namespace vb::hw::testing {

class U3DeviceEmulator::Cable final : public Transport {
 public:
  explicit Cable(U3DeviceEmulator* d) : d_(d) {}
  IoStatus Write(std::uint8_t ep, const std::uint8_t* data, std::size_t size, int) override {
    return d_->HostWrite(ep, data, size);
  }
  IoStatus Read(std::uint8_t ep, std::uint8_t* buf, std::size_t capacity, std::size_t* received, int) override {
    return d_->HostRead(ep, buf, capacity, received);
  }
  Status Reopen() override {
    if (!d_->plugged_) return Status::Unavailable("no U3 (0cd5:0003) on the bus");
    return Status::Ok();
  }
  std::string Describe() const override { return "emulated u3 " + std::to_string(d_->opt_.serial); }

 private:
  U3DeviceEmulator* d_;
};

U3DeviceEmulator::U3DeviceEmulator(U3DeviceOptions options) : opt_(std::move(options)), valve_(opt_.valve) {
  RunConfig rc;
  rc.supply_V = opt_.supply_V;
  rc.sample_rate_Hz = 0.0;
  (void)valve_.Configure(rc);
  (void)valve_.Start(nullptr);
}

std::unique_ptr<Transport> U3DeviceEmulator::Connect() { return std::make_unique<Cable>(this); }

int U3DeviceEmulator::gate() const { return plugged_ ? valve_.simulator().gate() : 0; }

void U3DeviceEmulator::Reset() {
  ++resets_;
  timers_ = 0;
  fio_dir_ = fio_state_ = 0;  // every pin an input: the gate resistor pulls the gate low
  streaming_ = stream_configured_ = false;
  watchdog_ = u3::Watchdog{};
  responses_.clear();
  ApplyOutputs();
}

void U3DeviceEmulator::Unplug() {
  Reset();
  plugged_ = false;
}

void U3DeviceEmulator::Replug() { plugged_ = true; }

void U3DeviceEmulator::ApplyOutputs(bool restart_carrier) {
  const std::uint8_t bit = static_cast<std::uint8_t>(1u << pin_offset_);
  if (timers_ > 0) {
    const double f = u3::TimerClockHz(clock_) / (timer_mode_ == u3::kTimerModePwm8 ? 256.0 : 65536.0);
    const double duty = U3Duty(timer_mode_, timer_value_);
    SwitchCommand c = SwitchCommand::Pwm(duty, f);
    c.restart_carrier = restart_carrier;
    (void)valve_.Apply(c);
    return;
  }
  const bool high = (fio_dir_ & bit) && (fio_state_ & bit);
  (void)valve_.Apply(SwitchCommand::Gate(high ? 1 : 0));
}

IoStatus U3DeviceEmulator::HostWrite(std::uint8_t ep, const std::uint8_t* d, std::size_t size) {
  if (!plugged_) return IoStatus::kDisconnected;
  if (ep != u3::kEpCommandOut || size < 2) return IoStatus::kError;
  last_command_t_s_ = t_s_;
  u3::Packet resp;
  // Normal commands: [Checksum8, cmd].
  if (d[1] == u3::kStreamStart || d[1] == u3::kStreamStop) {
    if (size != 2 || d[0] != u3::Checksum8(d, size)) {
      ++bad_checksums_;
      resp.Push({u3::kBadChecksumReply, u3::kBadChecksumReply});
      Respond(resp);
      return IoStatus::kOk;
    }
    std::uint8_t err = 0;
    if (d[1] == u3::kStreamStart) {
      if (!stream_configured_ || streaming_) err = 48;
      streaming_ = err == 0;
      scan_ = 0;
      packet_number_ = 0;
    } else {
      streaming_ = false;
    }
    resp.Push({0, static_cast<std::uint8_t>(d[1] + 1), err, 0});
    resp[0] = u3::Checksum8(resp.data(), resp.size());
    Respond(resp);
    return IoStatus::kOk;
  }
  if (d[1] != 0xF8 || size < 6 || d[2] != (size - 6) / 2 || (d[4] | (d[5] << 8)) != u3::Checksum16(d, size) ||
      d[0] != u3::Checksum8(d, 6)) {
    ++bad_checksums_;
    resp.Push({u3::kBadChecksumReply, u3::kBadChecksumReply});
    Respond(resp);
    return IoStatus::kOk;
  }
  switch (static_cast<u3::Cmd>(d[3])) {
    case u3::Cmd::kConfigU3: {
      u3::DeviceInfo info;
      info.serial = opt_.serial;
      info.product_id = u3::kProductId;
      info.firmware_x100 = 146;
      info.hardware_x100 = 130;
      info.version_info = 2;  // U3-LV
      Respond(u3::EncodeConfigU3Response(info, fio_analog_,
                                         static_cast<std::uint8_t>(timers_ | (pin_offset_ << 4))));
      break;
    }
    case u3::Cmd::kConfigIO: {
      u3::ConfigIO c;
      std::uint8_t err = 0;
      if (!u3::DecodeConfigIO(d, size, &c).ok() || c.timers_enabled > 2 || c.pin_offset < 4 || c.pin_offset > 8) {
        err = 40;
      } else {
        if (timers_ == 0 && c.timers_enabled > 0) timer_enabled_t_s_ = t_s_;
        timers_ = c.timers_enabled;
        pin_offset_ = c.pin_offset;
        fio_analog_ = c.fio_analog;
        ApplyOutputs();
      }
      Respond(u3::EncodeConfigIOResponse(u3::ConfigIO{static_cast<std::uint8_t>(timers_), pin_offset_, fio_analog_},
                                         err));
      break;
    }
    case u3::Cmd::kConfigTimerClock: {
      u3::TimerClock c;
      bool write = false;
      if (u3::DecodeTimerClock(d, size, &c, &write).ok() && write) {
        clock_ = c;
        if (timers_ > 0) ApplyOutputs();
      }
      Respond(u3::EncodeTimerClockResponse(clock_, 0));
      break;
    }
    case u3::Cmd::kWatchdog: {
      u3::Watchdog w;
      if (u3::DecodeWatchdog(d, size, &w).ok()) watchdog_ = w;
      Respond(u3::EncodeWatchdogResponse(watchdog_, 0));
      break;
    }
    case u3::Cmd::kStreamConfig: {
      u3::StreamConfig c;
      std::uint8_t err = 0;
      if (streaming_) err = 48;
      else if (!u3::DecodeStreamConfig(d, size, &c).ok() || c.channels.empty() ||
               c.samples_per_packet % c.channels.size() != 0)
        err = 40;
      else {
        stream_ = c;
        stream_configured_ = true;
      }
      Respond(u3::EncodeStreamConfigResponse(err));
      break;
    }
    case u3::Cmd::kFeedback: {
      std::uint8_t data[64];
      std::size_t n = 0;
      std::uint8_t err = 0, frame = 0;
      bool restart = false;
      for (std::size_t k = 7; k < size && err == 0; ++frame) {
        const std::uint8_t type = d[k];
        if (type == 0 && k + 1 >= size) break;  // padding
        if (type == u3::kIoBitDirWrite || type == u3::kIoBitStateWrite) {
          if (k + 1 >= size) { err = 1; break; }
          const std::uint8_t io = d[k + 1] & 0x1F, on = d[k + 1] >> 7;
          if (io < 8) {
            const std::uint8_t bit = static_cast<std::uint8_t>(1u << io);
            if (type == u3::kIoBitDirWrite) fio_dir_ = on ? (fio_dir_ | bit) : (fio_dir_ & ~bit);
            else {
              fio_dir_ |= bit;
              fio_state_ = on ? (fio_state_ | bit) : (fio_state_ & ~bit);
            }
          }
          k += 2;
        } else if (type == u3::kIoTimer0Config) {
          if (k + 3 >= size) { err = 1; break; }
          timer_mode_ = d[k + 1];
          timer_value_ = static_cast<std::uint16_t>(d[k + 2] | (d[k + 3] << 8));
          restart = restart || t_s_ == timer_enabled_t_s_;
          k += 4;
        } else if (type == u3::kIoAin) {
          const std::uint16_t counts = static_cast<std::uint16_t>(
              std::clamp(std::lround(i_A_ / opt_.amps_per_volt / u3::kNominalAinSlope_V), 0L, 65535L));
          data[n++] = static_cast<std::uint8_t>(counts);
          data[n++] = static_cast<std::uint8_t>(counts >> 8);
          k += 3;
        } else if (type == 0) {
          ++k;
        } else {
          err = 1;
        }
      }
      ApplyOutputs(restart);
      Respond(u3::EncodeFeedbackResponse(err, frame, data, n));
      break;
    }
    default:
      resp.Push({u3::kBadChecksumReply, u3::kBadChecksumReply});  // unknown: treated as garbage
      Respond(resp);
  }
  return IoStatus::kOk;
}

void U3DeviceEmulator::ProducePacket() {
  const int per_scan = static_cast<int>(stream_.channels.size());
  const int scans = stream_.samples_per_packet / per_scan;
  const double rate = u3::ScanRateHz(stream_);
  u3::StreamData out;
  out.count = stream_.samples_per_packet;
  out.packet_number = packet_number_++;
  for (int s = 0; s < scans; ++s, ++scan_) {
    const double ts = static_cast<double>(scan_) / rate;
    if (ts > t_s_) {
      Measurement m;
      (void)valve_.AdvanceTo(ts, &m);
      i_A_ = m.current_A;
      t_s_ = ts;
    }
    if (watchdog_.enable && t_s_ - last_command_t_s_ > watchdog_.timeout_s) {
      Reset();
      return;
    }
    for (int c = 0; c < per_scan; ++c) {
      const auto [pos, neg] = stream_.channels[c];
      std::uint16_t v = 0;
      if (pos == u3::kStreamChannelFioEio) {
        std::uint8_t fio = fio_state_ & fio_dir_;
        const std::uint8_t bit = static_cast<std::uint8_t>(1u << pin_offset_);
        fio = valve_.simulator().gate() == 1 ? (fio | bit) : (fio & ~bit);
        v = fio;
      } else {
        (void)neg;
        v = static_cast<std::uint16_t>(
            std::clamp(std::lround(i_A_ / opt_.amps_per_volt / u3::kNominalAinSlope_V), 0L, 65535L));
      }
      out.samples[s * per_scan + c] = v;
    }
  }
  responses_stream_.push_back(u3::Encode(out));
}

IoStatus U3DeviceEmulator::HostRead(std::uint8_t ep, std::uint8_t* buf, std::size_t capacity, std::size_t* received) {
  *received = 0;
  if (!plugged_) return IoStatus::kDisconnected;
  std::deque<u3::Packet>* q = nullptr;
  if (ep == u3::kEpResponseIn) {
    q = &responses_;
  } else if (ep == u3::kEpStreamIn) {
    if (responses_stream_.empty() && streaming_) ProducePacket();
    q = &responses_stream_;
  } else {
    return IoStatus::kError;
  }
  if (q->empty()) return IoStatus::kTimeout;
  const u3::Packet p = q->front();
  q->pop_front();
  const std::size_t n = std::min(capacity, p.size());
  std::memcpy(buf, p.data(), n);
  *received = n;
  return IoStatus::kOk;
}

void U3DeviceEmulator::RunFor(double seconds) {
  const double until = t_s_ + seconds;
  while (plugged_ && streaming_ && t_s_ < until) ProducePacket();
  responses_stream_.clear();  // nobody read them
}

}  // namespace vb::hw::testing
