// FaultyTransport: wraps any Transport and injects the faults a USB bench meets, counted in packets read from
// one endpoint (0xFF: any), so a test can place a fault mid-run: silence (timeouts), short and corrupt
// packets, a broken checksum byte, a repeated (stale) packet, an unplug, and swallowed host writes (a host
// that stops talking: the device's watchdog must act).
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include "hw/transport.h"

namespace vb::hw::testing {

struct TransportFaults {
  std::uint8_t endpoint = 0xFF;   // whose reads are counted (0xFF: every read)
  long timeout_from_read = -1;    // this read and all after it time out
  long short_read_at = -1;        // this read delivers only short_bytes bytes
  std::size_t short_bytes = 17;
  long corrupt_read_at = -1;      // this read has a payload byte flipped (byte corrupt_byte)
  std::size_t corrupt_byte = 20;
  long bad_checksum_at = -1;      // this read has its checksum byte (checksum_byte) altered
  std::size_t checksum_byte = 63;
  long stale_read_at = -1;        // this read delivers the previous packet again
  long unplug_at_read = -1;       // from this read on the device is gone (on_unplug is called once)
  long drop_writes_from = -1;     // host writes from this one on vanish (reported as sent)
};

class FaultyTransport final : public Transport {
 public:
  FaultyTransport(std::unique_ptr<Transport> inner, TransportFaults faults, std::function<void()> on_unplug = {})
      : inner_(std::move(inner)), f_(faults), on_unplug_(std::move(on_unplug)) {}

  IoStatus Write(std::uint8_t endpoint, const std::uint8_t* data, std::size_t size, int timeout_ms) override;
  IoStatus Read(std::uint8_t endpoint, std::uint8_t* buf, std::size_t capacity, std::size_t* received,
                int timeout_ms) override;
  Status Reopen() override;
  std::string Describe() const override { return inner_->Describe(); }

  long reads() const { return reads_; }
  long writes() const { return writes_; }
  void set_faults(const TransportFaults& f) { f_ = f; }

 private:
  std::unique_ptr<Transport> inner_;
  TransportFaults f_;
  std::function<void()> on_unplug_;
  long reads_ = 0, writes_ = 0;
  bool unplugged_ = false;
  std::vector<std::uint8_t> last_;
};

}  // namespace vb::hw::testing
