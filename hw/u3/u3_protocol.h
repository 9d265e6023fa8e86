// LabJack U3 low-level protocol: the subset valvebench uses, encoded and decoded byte for byte from the
// public U3 User's Guide, section 5 "Low-level function reference" (docs/hw-protocol.md lists what came from
// the guide and what is uncertain). Both the host (U3Bench) and the test's device emulator use this codec;
// golden-byte tests pin it against the examples published with LabJack's own Python driver.
//
// Framing: "extended" commands are [Checksum8, 0xF8, words, command, Checksum16 LSB, MSB, data...] where
// words = (size - 6) / 2, Checksum16 is the 16-bit sum of bytes 6.., Checksum8 the folded sum of bytes 1..5.
// "Normal" commands are [Checksum8, command, ...] with Checksum8 the folded sum of bytes 1... Stream data
// packets arrive on their own bulk endpoint, framed like extended responses with byte 1 = 0xF9.
//
// USB: VID 0x0CD5, PID 0x0003; commands out on endpoint 0x01, responses in on 0x82, stream data in on 0x83.
//
// Errors: a device errorcode in a command response is FailedPrecondition (the device refused the request, as a
// HID bench reports a NAK); an errorcode in stream data is Aborted (as a HID device fault). Internal is kept for
// our own bugs (docs/hw-protocol.md).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "common/status.h"

namespace vb::hw::u3 {

inline constexpr std::uint16_t kVendorId = 0x0CD5;
inline constexpr std::uint16_t kProductId = 0x0003;
inline constexpr std::uint8_t kEpCommandOut = 0x01;
inline constexpr std::uint8_t kEpResponseIn = 0x82;
inline constexpr std::uint8_t kEpStreamIn = 0x83;
inline constexpr std::size_t kMaxPacket = 64;

// A packet of at most 64 bytes, on the stack: encoding allocates nothing (the control loop sends commands).
struct Packet {
  std::array<std::uint8_t, kMaxPacket> b{};
  std::size_t n = 0;
  void Push(std::uint8_t v) { if (n < kMaxPacket) b[n++] = v; }
  void Push(std::initializer_list<std::uint8_t> vs) { for (auto v : vs) Push(v); }
  void Resize(std::size_t size) { n = size < kMaxPacket ? size : kMaxPacket; }
  std::uint8_t& operator[](std::size_t k) { return b[k]; }
  std::uint8_t operator[](std::size_t k) const { return b[k]; }
  const std::uint8_t* data() const { return b.data(); }
  std::uint8_t* data() { return b.data(); }
  std::size_t size() const { return n; }
};

// Extended command numbers (byte 3) and normal command bytes.
enum class Cmd : std::uint8_t {
  kFeedback = 0x00,
  kConfigU3 = 0x08,
  kWatchdog = 0x09,
  kConfigTimerClock = 0x0A,
  kConfigIO = 0x0B,
  kStreamConfig = 0x11,
};
inline constexpr std::uint8_t kStreamStart = 0xA8;   // normal command; response byte 1 = 0xA9
inline constexpr std::uint8_t kStreamStop = 0xB0;    // normal command; response byte 1 = 0xB1
inline constexpr std::uint8_t kStreamDataByte1 = 0xF9;
inline constexpr std::uint8_t kStreamDataCmd = 0xC0;

// Feedback IOTypes used here (guide 5.2.5).
inline constexpr std::uint8_t kIoAin = 1;             // [1, PositiveChannel, NegativeChannel] -> 2 bytes
inline constexpr std::uint8_t kIoBitStateWrite = 11;  // [11, IONumber | State << 7] -> 0 bytes
inline constexpr std::uint8_t kIoBitDirWrite = 13;    // [13, IONumber | Direction << 7] -> 0 bytes
inline constexpr std::uint8_t kIoTimer0Config = 43;   // [43, TimerMode, Value LSB, MSB] -> 0 bytes
inline constexpr std::uint8_t kTimerModePwm16 = 0;
inline constexpr std::uint8_t kTimerModePwm8 = 1;
inline constexpr std::uint8_t kNegChannelSingleEnded = 31;
inline constexpr std::uint8_t kStreamChannelFioEio = 193;  // stream: FIO (LSB) and EIO (MSB) digital states

std::uint8_t Checksum8(const std::uint8_t* data, std::size_t size);    // folded sum of data[1..size)
std::uint16_t Checksum16(const std::uint8_t* data, std::size_t size);  // sum of data[6..size)

// Fills in byte 2 (words) and the checksums of an extended packet, in place.
void SealExtended(Packet* p);
// A normal two-byte command (StreamStart, StreamStop): [Checksum8, cmd].
Packet NormalCommand(std::uint8_t cmd);

// Checks an extended packet: size, byte 1 (0xF8 or, for stream data, 0xF9), words, command byte, both
// checksums. DataLoss naming the problem ("short packet", "bad Checksum16 ...").
Status CheckExtended(const std::uint8_t* data, std::size_t size, std::uint8_t byte1, std::uint8_t command,
                     std::size_t expected_size);
// A U3 answers a command whose checksums it rejects with these two bytes instead of a response.
inline constexpr std::uint8_t kBadChecksumReply = 0xB8;
// Checks a normal response [Checksum8, response byte, errorcode, 0].
Status CheckNormal(const std::uint8_t* data, std::size_t size, std::uint8_t response_byte);

// --- ConfigU3 (read only: WriteMask 0) ---
Packet EncodeConfigU3Read();
struct DeviceInfo {
  std::uint32_t serial = 0;
  std::uint16_t product_id = 0;
  std::uint16_t firmware_x100 = 0;   // 1.46 -> 146
  std::uint16_t hardware_x100 = 0;
  std::uint8_t version_info = 0;     // 2: U3-LV, 18: U3-HV
};
inline constexpr std::size_t kConfigU3ResponseSize = 38;
Status DecodeConfigU3Response(const std::uint8_t* data, std::size_t size, DeviceInfo* info);
// Device side.
Packet EncodeConfigU3Response(const DeviceInfo& info, std::uint8_t fio_analog,
                                                 std::uint8_t timer_counter_config);

// --- ConfigIO: timers on a pin offset, which FIO lines are analog ---
struct ConfigIO {
  std::uint8_t timers_enabled = 0;   // 0..2
  std::uint8_t pin_offset = 4;       // 4..8: Timer0 on FIO(pin_offset)
  std::uint8_t fio_analog = 0;       // bit k: FIOk analog
};
inline constexpr std::size_t kConfigIOSize = 12;
Packet Encode(const ConfigIO& c);
Status DecodeConfigIO(const std::uint8_t* data, std::size_t size, ConfigIO* c);  // command or response
Packet EncodeConfigIOResponse(const ConfigIO& c, std::uint8_t errorcode);

// --- ConfigTimerClock: base (write) and divisor ---
struct TimerClock {
  std::uint8_t base = 2;             // 0: 4 MHz, 1: 12 MHz, 2: 48 MHz, 3: 1 MHz/div, 4: 4 MHz/div,
                                     // 5: 12 MHz/div, 6: 48 MHz/div
  std::uint8_t divisor = 0;          // 0 means 256
};
inline constexpr std::size_t kConfigTimerClockSize = 10;
Packet Encode(const TimerClock& c);
Status DecodeTimerClock(const std::uint8_t* data, std::size_t size, TimerClock* c, bool* write);
Packet EncodeTimerClockResponse(const TimerClock& c, std::uint8_t errorcode);
double TimerClockHz(const TimerClock& c);

// --- Watchdog: reset the device when the host has been silent for timeout_s (whole seconds) ---
struct Watchdog {
  bool enable = false;
  bool reset_on_timeout = true;
  std::uint16_t timeout_s = 1;
};
inline constexpr std::size_t kWatchdogSize = 16;
Packet Encode(const Watchdog& w);
Status DecodeWatchdog(const std::uint8_t* data, std::size_t size, Watchdog* w);
Packet EncodeWatchdogResponse(const Watchdog& w, std::uint8_t errorcode);

// --- Feedback: a list of IOTypes in one packet ---
struct FeedbackBuilder {
  FeedbackBuilder() { p.Push({0, 0xF8, 0, 0x00, 0, 0, 0 /*echo*/}); }
  Packet p;
  std::size_t response_data = 0;     // bytes of data the response will carry
  void BitDirWrite(std::uint8_t io, bool output) {
    p.Push({kIoBitDirWrite, static_cast<std::uint8_t>((io % 20) | (output ? 0x80 : 0))});
  }
  void BitStateWrite(std::uint8_t io, bool high) {
    p.Push({kIoBitStateWrite, static_cast<std::uint8_t>((io % 20) | (high ? 0x80 : 0))});
  }
  void Timer0Config(std::uint8_t mode, std::uint16_t value) {
    p.Push({kIoTimer0Config, mode, static_cast<std::uint8_t>(value), static_cast<std::uint8_t>(value >> 8)});
  }
  void Ain(std::uint8_t positive, std::uint8_t negative) {
    p.Push({kIoAin, positive, negative});
    response_data += 2;
  }
  // Pads to an even size and seals. The response is 9 + response_data bytes, padded to even.
  Packet Finish();
  std::size_t ResponseSize() const { return (9 + response_data + 1) / 2 * 2; }
};
// Checks a Feedback response and its errorcode; *data points at the first data byte.
Status CheckFeedbackResponse(const std::uint8_t* data, std::size_t size, std::size_t expected_size);
Packet EncodeFeedbackResponse(std::uint8_t errorcode, std::uint8_t error_frame, const std::uint8_t* data,
                              std::size_t size);

// --- Stream ---
struct StreamConfig {
  std::uint8_t samples_per_packet = 25;  // 1..25
  bool clock_48MHz = false;              // else 4 MHz
  bool divide_by_256 = false;
  std::uint8_t resolution = 0;
  std::uint16_t scan_interval = 4000;    // scan rate = clock / scan_interval
  std::vector<std::pair<std::uint8_t, std::uint8_t>> channels;  // (positive, negative)
};
Packet Encode(const StreamConfig& c);
Status DecodeStreamConfig(const std::uint8_t* data, std::size_t size, StreamConfig* c);
inline constexpr std::size_t kStreamConfigResponseSize = 8;
Packet EncodeStreamConfigResponse(std::uint8_t errorcode);
double ScanRateHz(const StreamConfig& c);

struct StreamData {
  std::uint8_t packet_number = 0;    // +1 per packet, wraps at 256
  std::uint8_t errorcode = 0;
  std::uint8_t backlog = 0;
  int count = 0;                     // samples in this packet (= samples_per_packet)
  std::array<std::uint16_t, 25> samples{};
};
std::size_t StreamPacketSize(int samples_per_packet);  // 14 + 2 * samples_per_packet
Packet Encode(const StreamData& d);
// Checks framing and checksums; fills *d (samples resized to samples_per_packet).
Status DecodeStreamData(const std::uint8_t* data, std::size_t size, int samples_per_packet, StreamData* d);

// An errorcode for messages (the guide's errorcode table is the reference).
std::string ErrorcodeName(std::uint8_t code);

// The U3-LV's nominal single-ended AIN slope (0..2.44 V over 16 bits): volts per count. A real device's
// calibration constants (ReadMem) are not read yet: see docs/hw-protocol.md.
inline constexpr double kNominalAinSlope_V = 2.44 / 65536.0;

}  // namespace vb::hw::u3
