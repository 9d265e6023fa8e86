// The LabJack U3 protocol as a device (or a faulty USB link) answers: packets into every decoder.
// Input: byte 0 = flags (bit 0: reseal the extended checksums so the fuzzer gets past them; bits 1-5: samples
// per stream packet, 0..31, so out-of-range counts are tried too), the rest is the packet (at most 64 bytes
// arrive from the device; longer input is cut).
#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "hw/u3/u3_protocol.h"

namespace u3 = vb::hw::u3;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const bool reseal = (data[0] & 1) != 0;
  const int samples_per_packet = (data[0] >> 1) & 0x1F;
  ++data;
  --size;
  u3::Packet p;
  for (std::size_t k = 0; k < std::min(size, u3::kMaxPacket); ++k) p.Push(data[k]);
  if (reseal && p.size() >= 6) u3::SealExtended(&p);
  const std::uint8_t* d = p.data();
  const std::size_t n = p.size();

  u3::DeviceInfo info;
  (void)u3::DecodeConfigU3Response(d, n, &info);
  u3::ConfigIO io;
  if (u3::DecodeConfigIO(d, n, &io).ok()) (void)u3::Encode(io);
  u3::TimerClock clock;
  bool write = false;
  if (u3::DecodeTimerClock(d, n, &clock, &write).ok()) (void)u3::TimerClockHz(clock);
  u3::Watchdog wd;
  if (u3::DecodeWatchdog(d, n, &wd).ok()) (void)u3::Encode(wd);
  (void)u3::CheckFeedbackResponse(d, n, n);
  (void)u3::CheckNormal(d, n, u3::kStreamStart + 1);
  u3::StreamConfig sc;
  if (u3::DecodeStreamConfig(d, n, &sc).ok()) {
    (void)u3::ScanRateHz(sc);
    (void)u3::Encode(sc);
  }
  u3::StreamData sd;
  if (u3::DecodeStreamData(d, n, samples_per_packet, &sd).ok()) (void)u3::Encode(sd);
  if (n > 2) (void)u3::ErrorcodeName(d[2]);
  return 0;
}
