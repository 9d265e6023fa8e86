#include "hw/usb/list_attached.h"

#include "hw/hid/hidapi_transport.h"
#include "hw/u3/libusb_transport.h"

namespace vb::hw {

AttachedDevices ListAttachedDevices() {
  AttachedDevices out;
  if (!UsbBusPresent()) {
    out.bus_present = false;
    out.note = kNoUsbBusNote;
    return out;
  }
  auto hid = EnumerateHidBenches();
  if (hid.ok())
    out.devices.insert(out.devices.end(), hid->begin(), hid->end());
  else
    out.errors.push_back("hid: " + hid.status().message());
  auto u3 = EnumerateU3();
  if (u3.ok())
    out.devices.insert(out.devices.end(), u3->begin(), u3->end());
  else
    out.errors.push_back("u3: " + u3.status().message());
  if (out.devices.empty() && out.errors.empty()) out.note = "no hid or u3 bench is attached";
  return out;
}

}  // namespace vb::hw
