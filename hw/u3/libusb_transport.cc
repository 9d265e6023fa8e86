#include "hw/u3/libusb_transport.h"

#include <libusb.h>

#include <cstdio>

#include "hw/u3/u3_protocol.h"

namespace vb::hw {

namespace {

// libusb reads 0 as "wait forever": the protocol's 0 means "only what is already there".
int LibusbTimeout(int timeout_ms) { return timeout_ms <= 0 ? 1 : timeout_ms; }

IoStatus FromLibusb(int rc) {
  switch (rc) {
    case LIBUSB_SUCCESS: return IoStatus::kOk;
    case LIBUSB_ERROR_TIMEOUT: return IoStatus::kTimeout;
    case LIBUSB_ERROR_NO_DEVICE: return IoStatus::kDisconnected;
    default: return IoStatus::kError;
  }
}

Status Init(libusb_context** ctx) {
  if (!UsbBusPresent()) return Status::Unavailable(kNoUsbBusNote);
  const int rc = libusb_init(ctx);
  if (rc != 0) return Status::Unavailable(std::string("libusb_init: ") + libusb_error_name(rc));
  return Status::Ok();
}

class LibusbTransport final : public Transport {
 public:
  explicit LibusbTransport(int index) : index_(index) {}
  ~LibusbTransport() override {
    Close();
    if (ctx_ != nullptr) libusb_exit(ctx_);
  }

  Status Open() {
    Close();
    if (ctx_ == nullptr) VB_RETURN_IF_ERROR(Init(&ctx_));
    libusb_device** list = nullptr;
    const ssize_t n = libusb_get_device_list(ctx_, &list);
    if (n < 0) return Status::Unavailable(std::string("libusb_get_device_list: ") + libusb_error_name(int(n)));
    int seen = 0;
    int rc = LIBUSB_ERROR_NOT_FOUND;
    for (ssize_t k = 0; k < n && handle_ == nullptr; ++k) {
      libusb_device_descriptor desc;
      if (libusb_get_device_descriptor(list[k], &desc) != 0) continue;
      if (desc.idVendor != u3::kVendorId || desc.idProduct != u3::kProductId) continue;
      if (seen++ != index_) continue;
      rc = libusb_open(list[k], &handle_);
      if (rc != 0) handle_ = nullptr;
    }
    libusb_free_device_list(list, 1);
    if (handle_ == nullptr) {
      if (rc == LIBUSB_ERROR_ACCESS)
        return Status::Unavailable(Describe() + ": permission denied (install udev/60-valvebench.rules)");
      return Status::Unavailable(Describe() + ": not attached (" + std::to_string(seen) + " U3 found)");
    }
    libusb_set_auto_detach_kernel_driver(handle_, 1);
    rc = libusb_claim_interface(handle_, 0);
    if (rc != 0) {
      Close();
      return Status::Unavailable(Describe() + ": cannot claim interface 0: " + libusb_error_name(rc));
    }
    return Status::Ok();
  }

  IoStatus Write(std::uint8_t endpoint, const std::uint8_t* data, std::size_t size, int timeout_ms) override {
    if (handle_ == nullptr) return IoStatus::kDisconnected;
    int done = 0;
    const int rc = libusb_bulk_transfer(handle_, endpoint, const_cast<std::uint8_t*>(data), static_cast<int>(size),
                                        &done, LibusbTimeout(timeout_ms));
    if (rc == 0 && done != static_cast<int>(size)) return IoStatus::kError;
    return FromLibusb(rc);
  }

  IoStatus Read(std::uint8_t endpoint, std::uint8_t* buf, std::size_t capacity, std::size_t* received,
                int timeout_ms) override {
    *received = 0;
    if (handle_ == nullptr) return IoStatus::kDisconnected;
    int done = 0;
    const int rc =
        libusb_bulk_transfer(handle_, endpoint, buf, static_cast<int>(capacity), &done, LibusbTimeout(timeout_ms));
    *received = static_cast<std::size_t>(done);
    if (rc == LIBUSB_ERROR_TIMEOUT && done > 0) return IoStatus::kOk;
    return FromLibusb(rc);
  }

  Status Reopen() override { return Open(); }

  std::string Describe() const override { return "u3 0cd5:0003 #" + std::to_string(index_); }

 private:
  void Close() {
    if (handle_ != nullptr) {
      libusb_release_interface(handle_, 0);
      libusb_close(handle_);
    }
    handle_ = nullptr;
  }
  int index_;
  libusb_context* ctx_ = nullptr;
  libusb_device_handle* handle_ = nullptr;
};

}  // namespace

StatusOr<std::unique_ptr<Transport>> OpenLibusbU3Transport(int index) {
  auto t = std::make_unique<LibusbTransport>(index);
  VB_RETURN_IF_ERROR(t->Open());
  return std::unique_ptr<Transport>(std::move(t));
}

StatusOr<std::vector<AttachedDevice>> EnumerateU3() {
  std::vector<AttachedDevice> out;
  if (!UsbBusPresent()) return out;
  libusb_context* ctx = nullptr;
  VB_RETURN_IF_ERROR(Init(&ctx));
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(ctx, &list);
  for (ssize_t k = 0; k < n; ++k) {
    libusb_device_descriptor desc;
    if (libusb_get_device_descriptor(list[k], &desc) != 0) continue;
    if (desc.idVendor != u3::kVendorId || desc.idProduct != u3::kProductId) continue;
    AttachedDevice a;
    a.kind = "u3";
    a.vendor_id = desc.idVendor;
    a.product_id = desc.idProduct;
    a.product = "LabJack U3";
    a.path = "bus " + std::to_string(libusb_get_bus_number(list[k])) + " address " +
             std::to_string(libusb_get_device_address(list[k]));
    libusb_device_handle* h = nullptr;
    if (desc.iSerialNumber != 0 && libusb_open(list[k], &h) == 0) {
      unsigned char s[64] = {};
      if (libusb_get_string_descriptor_ascii(h, desc.iSerialNumber, s, sizeof s) > 0)
        a.serial = reinterpret_cast<char*>(s);
      libusb_close(h);
    }
    out.push_back(std::move(a));
  }
  if (n >= 0) libusb_free_device_list(list, 1);
  libusb_exit(ctx);
  return out;
}

}  // namespace vb::hw
