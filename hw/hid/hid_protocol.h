// The valvebench HID bench protocol, version 1 (docs/hw-protocol.md is the normative text; this is its codec).
//
// A microcontroller bench (e.g. an RP2040 with TinyUSB's generic HID, vendor usage page 0xFF00) exchanges
// 64-byte reports, little-endian, no report ID:
//   byte 0      report type (host->device 0x01..0x0A, device->host 0x81..0x84)
//   byte 1      protocol version (1)
//   bytes 2-5   sequence number, u32: +1 for every report sent in that direction
//   bytes 6-62  payload (per type, below)
//   byte 63     CRC-8 (polynomial 0x07, init 0x00, no reflection) of bytes 0-62
// Both sides encode and decode with these functions: the host in HidBench, the device side in the test
// emulator (hw/testing); golden-byte tests pin the layout so a symmetric mistake cannot hide.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "common/status.h"

namespace vb::hw::hid {

inline constexpr std::size_t kReportSize = 64;
inline constexpr std::uint8_t kProtocolVersion = 1;
inline constexpr int kMaxSamplesPerReport = 20;
inline constexpr std::uint16_t kUsagePage = 0xFF00;  // vendor-defined

using Report = std::array<std::uint8_t, kReportSize>;

enum class Type : std::uint8_t {
  // host -> device
  kIdentify = 0x01,    // -> Identity
  kConfigure = 0x02,   // -> Ack
  kStart = 0x03,       // -> Ack, then Samples from index 0
  kStop = 0x04,        // -> Ack; sampling stops, safe state
  kSetPwm = 0x05,      // no answer (fast path); a bad value answers Fault(kBadCommand)
  kSetGate = 0x06,     // no answer
  kSetLoop = 0x07,     // -> Ack
  kHeartbeat = 0x08,   // no answer; feeds the watchdog (every host report does)
  kSafe = 0x09,        // no answer; gate low, PWM stopped, on-device loop off
  kClearFault = 0x0A,  // -> Ack
  // device -> host
  kIdentity = 0x81,
  kAck = 0x82,
  kSamples = 0x83,
  kFault = 0x84,
};
const char* TypeName(Type t);

// Capability flags in Identity.flags.
inline constexpr std::uint8_t kCapHBridge = 1 << 0;
inline constexpr std::uint8_t kCapLoopOpen = 1 << 1;
inline constexpr std::uint8_t kCapLoopHysteresis = 1 << 2;
inline constexpr std::uint8_t kCapLoopPi = 1 << 3;

struct Identity {                      // payload offsets
  std::uint16_t firmware_version = 0;  // 6-7
  std::uint8_t flags = 0;              // 8: kCap*
  std::uint8_t current_channels = 1;   // 9
  std::uint32_t max_supply_mV = 0;     // 10-13
  float min_pwm_Hz = 0.0f;             // 14-17
  float max_pwm_Hz = 0.0f;             // 18-21
  std::uint32_t max_sample_rate_Hz = 0;  // 22-25
  std::uint16_t max_report_rate_Hz = 0;  // 26-27: at most 1000 on a full-speed interrupt pipe
  std::uint32_t max_inner_loop_Hz = 0;   // 28-31: rate of the on-device current loops
  std::uint32_t current_lsb_nA = 0;      // 32-35: current per sample count
  std::uint32_t max_current_mA = 0;      // 36-39: the device's own overcurrent trip
  char serial[16] = {};                  // 40-55: ASCII, NUL padded
  std::uint16_t min_watchdog_ms = 0;     // 56-57
};

struct Configure {
  std::uint32_t sample_rate_Hz = 0;      // 6-9
  std::uint8_t samples_per_report = 1;   // 10: 1..20
  std::uint16_t watchdog_ms = 0;         // 11-12: > 0; gate forced low if no host report for this long
  std::uint32_t max_current_mA = 0;      // 13-16: 0 = the device's maximum
};

struct SetPwm {
  float carrier_Hz = 0.0f;               // 6-9
  std::uint16_t duty = 0;                // 10-11: duty = value / 65535
  bool restart_carrier = false;          // 12 bit 0
};

struct SetGate {
  std::int8_t level = 0;                 // 6: -1 (H-bridge only), 0, 1
};

enum class LoopMode : std::uint8_t { kHost = 0, kOpenLoop = 1, kHysteresis = 2, kPi = 3 };
struct SetLoop {
  LoopMode mode = LoopMode::kHost;       // 6
  float setpoint = 0.0f;                 // 7-10: A (open loop: duty)
  float band_A = 0.0f;                   // 11-14: hysteresis band (full width)
  float kp_V_per_A = 0.0f;               // 15-18
  float ki_V_per_A_s = 0.0f;             // 19-22
  float carrier_Hz = 0.0f;               // 23-26: PWM carrier of open-loop and PI modes
  std::uint32_t loop_rate_Hz = 0;        // 27-30
};

enum class AckResult : std::uint8_t { kOk = 0, kBadParameter = 1, kBadState = 2, kUnsupported = 3 };
struct Ack {
  Type acked_type = Type::kIdentify;     // 6
  std::uint32_t acked_seq = 0;           // 7-10: the host report answered
  AckResult result = AckResult::kOk;     // 11
  std::uint8_t field_offset = 0;         // 12: byte offset of the offending field (kBadParameter)
};

inline constexpr std::uint8_t kSamplesOverrun = 1 << 0;  // samples were dropped before this report
inline constexpr std::uint8_t kSamplesSafe = 1 << 1;     // the device is in its safe state
struct Samples {
  std::uint32_t first_index = 0;         // 6-9: sample k is at t = k / sample_rate_Hz from Start
  std::uint8_t count = 0;                // 10: 1..20
  std::uint8_t flags = 0;                // 11
  std::uint32_t gate_bits = 0;           // 12-15: bit k = gate high during sample k
  std::uint32_t last_host_seq = 0;       // 16-19: the newest host report processed
  std::int16_t current[kMaxSamplesPerReport] = {};  // 20-59: current_lsb_nA per count
};

enum class FaultCode : std::uint8_t {
  kWatchdog = 1,      // value: ms since the last host report
  kOvercurrent = 2,   // value: A
  kSupplyLow = 3,     // value: V
  kOvertemperature = 4,  // value: degC of the driver
  kBadReport = 5,     // value: the type byte of the rejected report (CRC, length or version wrong)
  kBadCommand = 6,    // value: the type byte; a fast-path command with a parameter out of range
  kOverrun = 7,       // value: samples dropped (the host did not read fast enough)
};
const char* FaultName(FaultCode c);
struct Fault {
  FaultCode code = FaultCode::kWatchdog;  // 6
  std::uint32_t sample_index = 0;         // 7-10: when
  float value = 0.0f;                     // 11-14
};

std::uint8_t Crc8(const std::uint8_t* data, std::size_t size);

struct Header {
  Type type = Type::kIdentify;
  std::uint32_t seq = 0;
};
// Checks length, CRC and version of a received report. DataLoss naming the problem ("short report: 17 of 64
// bytes", "corrupt report: CRC ...", "protocol version 2, expected 1").
Status ParseHeader(const std::uint8_t* data, std::size_t size, Header* header);

// Encoders: a sealed report (header, payload, CRC).
Report Encode(Type bare_type, std::uint32_t seq);  // types without payload
Report Encode(const Identity& m, std::uint32_t seq);
Report Encode(const Configure& m, std::uint32_t seq);
Report Encode(const SetPwm& m, std::uint32_t seq);
Report Encode(const SetGate& m, std::uint32_t seq);
Report Encode(const SetLoop& m, std::uint32_t seq);
Report Encode(const Ack& m, std::uint32_t seq);
Report Encode(const Samples& m, std::uint32_t seq);
Report Encode(const Fault& m, std::uint32_t seq);

// Decoders of a report whose header has been parsed. InvalidArgument naming the field for values out of
// their range (a samples count of 0 or > 20, ...).
Status Decode(const Report& r, Identity* m);
Status Decode(const Report& r, Configure* m);
Status Decode(const Report& r, SetPwm* m);
Status Decode(const Report& r, SetGate* m);
Status Decode(const Report& r, SetLoop* m);
Status Decode(const Report& r, Ack* m);
Status Decode(const Report& r, Samples* m);
Status Decode(const Report& r, Fault* m);

std::string SerialOf(const Identity& id);

}  // namespace vb::hw::hid
