// Every USB device a hardware bench could use, from every backend (hidapi, libusb), for `benchctl benches
// --local` and the server's ListBenches. Never fails: a backend that cannot enumerate adds an error line,
// and a machine without a USB bus says so.
#pragma once

#include "hw/attached.h"

namespace vb::hw {

AttachedDevices ListAttachedDevices();

}  // namespace vb::hw
