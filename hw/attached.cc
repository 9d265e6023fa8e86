#include "hw/attached.h"

#include <filesystem>
#include <system_error>

namespace vb::hw {

bool UsbBusPresent() {
  std::error_code ec;
  return std::filesystem::exists("/sys/bus/usb", ec);
}

}  // namespace vb::hw
