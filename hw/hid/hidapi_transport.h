// The real HID transport: hidapi (hidraw backend) to a valvebench HID bench, and enumeration of attached
// vendor-page (0xFF00) HID devices. Opens by vendor/product id and, if given, serial number, so Reopen()
// finds the same device again after an unplug.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "hw/transport.h"
#include "hw/attached.h"

namespace vb::hw {

struct HidDeviceId {
  std::uint16_t vendor_id = 0x2E8A;  // Raspberry Pi (RP2040); set to what the firmware reports
  std::uint16_t product_id = 0x10C0;
  std::string serial;                // empty = the first match
};

// NotFound / Unavailable naming the device when it is not there (or when there is no USB bus at all).
StatusOr<std::unique_ptr<Transport>> OpenHidapiTransport(const HidDeviceId& id);

// HID devices on the vendor-defined usage page 0xFF00 (what a valvebench bench firmware presents).
StatusOr<std::vector<AttachedDevice>> EnumerateHidBenches();

}  // namespace vb::hw
