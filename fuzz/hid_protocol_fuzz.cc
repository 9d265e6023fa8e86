// The HID bench protocol as a device (or anything pretending to be one) sends it: 64-byte reports into
// ParseHeader and every decoder. Input: byte 0 = flags (bit 0: reseal the CRC so the fuzzer gets past it),
// the rest is the report (any length; ParseHeader must refuse short ones).
#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "hw/hid/hid_protocol.h"

namespace hid = vb::hw::hid;

namespace {
template <typename M>
void DecodeAndReencode(const hid::Report& r, std::uint32_t seq) {
  M m;
  if (hid::Decode(r, &m).ok()) (void)hid::Encode(m, seq);
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const bool reseal = (data[0] & 1) != 0;
  ++data;
  --size;
  hid::Report r{};
  std::copy_n(data, std::min(size, r.size()), r.begin());
  if (reseal && size >= hid::kReportSize) r[hid::kReportSize - 1] = hid::Crc8(r.data(), hid::kReportSize - 1);
  hid::Header h;
  if (!hid::ParseHeader(reseal ? r.data() : data, size, &h).ok()) return 0;
  (void)hid::TypeName(h.type);
  DecodeAndReencode<hid::Identity>(r, h.seq);
  DecodeAndReencode<hid::Configure>(r, h.seq);
  DecodeAndReencode<hid::SetPwm>(r, h.seq);
  DecodeAndReencode<hid::SetGate>(r, h.seq);
  DecodeAndReencode<hid::SetLoop>(r, h.seq);
  DecodeAndReencode<hid::Ack>(r, h.seq);
  DecodeAndReencode<hid::Samples>(r, h.seq);
  hid::Fault f;
  if (hid::Decode(r, &f).ok()) (void)hid::FaultName(f.code);
  hid::Identity id;
  if (hid::Decode(r, &id).ok()) (void)hid::SerialOf(id);
  return 0;
}
