#include "hw/hid/hidapi_transport.h"

#include <fmt/format.h>
#include <hidapi.h>

#include <array>
#include <cstdio>
#include <cstring>
#include <mutex>

#include "hw/hid/hid_protocol.h"

namespace vb::hw {

namespace {

Status InitOnce() {
  static std::once_flag once;
  static int rc = 0;
  std::call_once(once, [] { rc = hid_init(); });
  if (rc != 0) return Status::Unavailable("hidapi: hid_init failed");
  return Status::Ok();
}

std::string Narrow(const wchar_t* w) {
  std::string s;
  if (w == nullptr) return s;
  for (; *w != 0; ++w) s += (*w < 128) ? static_cast<char>(*w) : '?';
  return s;
}

std::string Hex4(unsigned v) {
  return fmt::format("{:04x}", v & 0xFFFF);
}

class HidapiTransport final : public Transport {
 public:
  explicit HidapiTransport(HidDeviceId id) : id_(std::move(id)) {}
  ~HidapiTransport() override { Close(); }

  Status Open() {
    VB_RETURN_IF_ERROR(InitOnce());
    Close();
    std::wstring wserial(id_.serial.begin(), id_.serial.end());
    dev_ = hid_open(id_.vendor_id, id_.product_id, id_.serial.empty() ? nullptr : wserial.c_str());
    if (dev_ == nullptr) {
      if (!UsbBusPresent()) return Status::Unavailable(Describe() + ": " + kNoUsbBusNote);
      return Status::Unavailable(Describe() + ": not attached, or no permission (udev/60-valvebench.rules)");
    }
    return Status::Ok();
  }

  IoStatus Write(std::uint8_t, const std::uint8_t* data, std::size_t size, int) override {
    if (dev_ == nullptr) return IoStatus::kDisconnected;
    // hidapi wants the report id first: 0 for a device without report ids, then the 64 bytes.
    std::array<std::uint8_t, hid::kReportSize + 1> buf{};
    const std::size_t n = std::min(size, hid::kReportSize);
    std::memcpy(buf.data() + 1, data, n);
    const int rc = hid_write(dev_, buf.data(), buf.size());
    if (rc < 0) return Gone();
    return IoStatus::kOk;
  }

  IoStatus Read(std::uint8_t, std::uint8_t* buf, std::size_t capacity, std::size_t* received,
                int timeout_ms) override {
    *received = 0;
    if (dev_ == nullptr) return IoStatus::kDisconnected;
    const int rc = hid_read_timeout(dev_, buf, capacity, timeout_ms);
    if (rc < 0) return Gone();
    if (rc == 0) return IoStatus::kTimeout;
    *received = static_cast<std::size_t>(rc);
    return IoStatus::kOk;
  }

  Status Reopen() override { return Open(); }

  std::string Describe() const override {
    return "hid " + Hex4(id_.vendor_id) + ":" + Hex4(id_.product_id) +
           (id_.serial.empty() ? std::string() : " serial " + id_.serial);
  }

 private:
  IoStatus Gone() {
    // hidraw reports an unplugged device as a failed read or write: close it; Reopen() brings it back.
    Close();
    return IoStatus::kDisconnected;
  }
  void Close() {
    if (dev_ != nullptr) hid_close(dev_);
    dev_ = nullptr;
  }
  HidDeviceId id_;
  hid_device* dev_ = nullptr;
};

}  // namespace

StatusOr<std::unique_ptr<Transport>> OpenHidapiTransport(const HidDeviceId& id) {
  auto t = std::make_unique<HidapiTransport>(id);
  VB_RETURN_IF_ERROR(t->Open());
  return std::unique_ptr<Transport>(std::move(t));
}

StatusOr<std::vector<AttachedDevice>> EnumerateHidBenches() {
  std::vector<AttachedDevice> out;
  if (!UsbBusPresent()) return out;
  VB_RETURN_IF_ERROR(InitOnce());
  hid_device_info* all = hid_enumerate(0, 0);
  for (hid_device_info* d = all; d != nullptr; d = d->next) {
    if (d->usage_page != hid::kUsagePage) continue;
    AttachedDevice a;
    a.kind = "hid";
    a.vendor_id = d->vendor_id;
    a.product_id = d->product_id;
    a.serial = Narrow(d->serial_number);
    a.product = Narrow(d->product_string);
    a.path = d->path != nullptr ? d->path : "";
    out.push_back(std::move(a));
  }
  hid_free_enumeration(all);
  return out;
}

}  // namespace vb::hw
