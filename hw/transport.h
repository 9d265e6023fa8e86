// Transport: how a hardware bench's protocol code reaches its device (after LevelDB's Env). The real ones wrap
// hidapi (hw/hid) and libusb (hw/u3); tests put a device emulator that speaks the device side byte for byte
// (hw/testing) behind the same interface, optionally through a fault-injecting wrapper.
//
// One packet per call. No allocation and no exceptions: the calls sit in the control loop.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "common/status.h"

namespace vb::hw {

enum class IoStatus : std::uint8_t {
  kOk,
  kTimeout,        // nothing within the timeout
  kDisconnected,   // the device went away (unplugged, reset); Reopen() may bring it back
  kError,          // any other failure of the bus or the OS
};
const char* IoStatusName(IoStatus s);

class Transport {
 public:
  Transport() = default;
  Transport(const Transport&) = delete;
  Transport& operator=(const Transport&) = delete;
  virtual ~Transport() = default;

  // Sends one packet. `endpoint` is the USB endpoint address for bulk devices; HID transports ignore it
  // (a HID device has one interrupt OUT pipe for output reports).
  virtual IoStatus Write(std::uint8_t endpoint, const std::uint8_t* data, std::size_t size, int timeout_ms) = 0;
  // Receives one packet into buf (at most capacity bytes); *received says how many arrived.
  virtual IoStatus Read(std::uint8_t endpoint, std::uint8_t* buf, std::size_t capacity, std::size_t* received,
                        int timeout_ms) = 0;
  // Closes and opens the same device again (by serial number): reconnect after an unplug.
  virtual Status Reopen() = 0;
  // "hid 2e8a:10c0 serial E660583883 (/dev/hidraw3)": for messages.
  virtual std::string Describe() const = 0;
};

// The Status a protocol layer reports for a failed transfer: Unavailable, naming the operation and the device.
Status TransportError(IoStatus s, const char* operation, const Transport& t, int timeout_ms);

}  // namespace vb::hw
