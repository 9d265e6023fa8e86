// What is plugged in: the USB devices a hardware bench could use, as enumeration reports them. A machine
// without a USB bus (a container, a CI runner) is a normal answer, not an error: bus_present is false and
// `note` says why.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"

namespace vb::hw {

struct AttachedDevice {
  std::string kind;            // "hid" or "u3"
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  std::string serial;          // as the USB descriptor gives it ("" if none)
  std::string product;         // product string
  std::string path;            // hidraw path or "bus 1 address 7"
};

struct AttachedDevices {
  bool bus_present = true;
  std::string note;            // e.g. "no USB bus on this machine (/sys/bus/usb is missing)"
  std::vector<AttachedDevice> devices;
  std::vector<std::string> errors;  // a backend that failed, with the reason (the others still list)
};

// True if this machine has a USB bus the kernel exposes (/sys/bus/usb).
bool UsbBusPresent();
inline constexpr const char* kNoUsbBusNote = "no USB bus on this machine (/sys/bus/usb is missing)";

}  // namespace vb::hw
