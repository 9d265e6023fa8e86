#include "hw/testing/faulty_transport.h"

#include <algorithm>
#include <cstring>

namespace vb::hw::testing {

IoStatus FaultyTransport::Write(std::uint8_t endpoint, const std::uint8_t* data, std::size_t size, int timeout_ms) {
  if (unplugged_) return IoStatus::kDisconnected;
  const long n = writes_++;
  if (f_.drop_writes_from >= 0 && n >= f_.drop_writes_from) return IoStatus::kOk;
  return inner_->Write(endpoint, data, size, timeout_ms);
}

IoStatus FaultyTransport::Read(std::uint8_t endpoint, std::uint8_t* buf, std::size_t capacity, std::size_t* received,
                               int timeout_ms) {
  *received = 0;
  if (unplugged_) return IoStatus::kDisconnected;
  const bool counted = f_.endpoint == 0xFF || f_.endpoint == endpoint;
  const long n = counted ? reads_++ : -1;
  if (counted && f_.unplug_at_read >= 0 && n >= f_.unplug_at_read) {
    unplugged_ = true;
    if (on_unplug_) on_unplug_();
    return IoStatus::kDisconnected;
  }
  if (counted && f_.timeout_from_read >= 0 && n >= f_.timeout_from_read) return IoStatus::kTimeout;
  if (counted && n == f_.stale_read_at && !last_.empty()) {
    const std::size_t k = std::min(capacity, last_.size());
    std::memcpy(buf, last_.data(), k);
    *received = k;
    return IoStatus::kOk;
  }
  const IoStatus io = inner_->Read(endpoint, buf, capacity, received, timeout_ms);
  if (io != IoStatus::kOk) return io;
  if (counted) last_.assign(buf, buf + *received);
  if (counted && n == f_.short_read_at) *received = std::min(*received, f_.short_bytes);
  if (counted && n == f_.corrupt_read_at && f_.corrupt_byte < *received) buf[f_.corrupt_byte] ^= 0x10;
  if (counted && n == f_.bad_checksum_at && f_.checksum_byte < *received) buf[f_.checksum_byte] ^= 0x5A;
  return IoStatus::kOk;
}

Status FaultyTransport::Reopen() {
  Status st = inner_->Reopen();
  if (st.ok()) {
    unplugged_ = false;
    f_.unplug_at_read = -1;  // plugged back in: the unplug happened once
  }
  return st;
}

}  // namespace vb::hw::testing
