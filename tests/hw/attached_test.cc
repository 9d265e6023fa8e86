// Enumeration and the real transports on whatever machine the tests run on: with no USB bus (a container,
// CI) they must say so cleanly, never crash; with a bus they list what is there.
#include <gtest/gtest.h>

#include "hw/hid/hidapi_transport.h"
#include "hw/u3/libusb_transport.h"
#include "hw/usb/list_attached.h"

namespace vb::hw {
namespace {

TEST(Attached, ListsOrSaysThereIsNoUsbBus) {
  const AttachedDevices a = ListAttachedDevices();
  EXPECT_EQ(a.bus_present, UsbBusPresent());
  if (!a.bus_present) {
    EXPECT_EQ(a.note, kNoUsbBusNote);
    EXPECT_TRUE(a.devices.empty());
    EXPECT_TRUE(a.errors.empty());
  }
  for (const auto& d : a.devices) {
    EXPECT_TRUE(d.kind == "hid" || d.kind == "u3") << d.kind;
    if (d.kind == "u3") {
      EXPECT_EQ(d.vendor_id, 0x0CD5);
    }
  }
}

TEST(Attached, OpeningAMissingDeviceNamesIt) {
  HidDeviceId id;
  id.vendor_id = 0x2E8A;
  id.product_id = 0x10C0;
  id.serial = "NO-SUCH-BENCH";
  auto hid = OpenHidapiTransport(id);
  ASSERT_FALSE(hid.ok());
  EXPECT_EQ(hid.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(hid.status().message().find("hid 2e8a:10c0 serial NO-SUCH-BENCH"), std::string::npos)
      << hid.status().message();
  if (!UsbBusPresent()) {
    EXPECT_NE(hid.status().message().find("no USB bus"), std::string::npos);
  }
  auto u3 = OpenLibusbU3Transport(99);  // the hundredth U3: not attached anywhere
  ASSERT_FALSE(u3.ok());
  EXPECT_EQ(u3.status().code(), StatusCode::kUnavailable);
  if (!UsbBusPresent()) {
    EXPECT_NE(u3.status().message().find("no USB bus"), std::string::npos);
  }
}

}  // namespace
}  // namespace vb::hw
