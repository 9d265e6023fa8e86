// The real U3 transport: libusb-1.0 bulk transfers to a LabJack U3 (VID 0x0CD5, PID 0x0003), interface 0,
// endpoints 0x01 (commands out), 0x82 (responses in), 0x83 (stream in). Every transfer has a timeout; an
// unplugged device reads as kDisconnected and Reopen() looks for a U3 again (U3Bench then checks the serial
// number with ConfigU3, since the U3's USB descriptor is not relied on for it).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "hw/attached.h"
#include "hw/transport.h"

namespace vb::hw {

// Opens the first U3 on the bus (index 0) or the index-th one. Unavailable naming the reason when there is
// none, or no USB bus at all.
StatusOr<std::unique_ptr<Transport>> OpenLibusbU3Transport(int index = 0);

StatusOr<std::vector<AttachedDevice>> EnumerateU3();

}  // namespace vb::hw
