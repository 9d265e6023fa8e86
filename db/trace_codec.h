// How a TraceChunk is stored in a trace_chunks row (docs/store.md, "Trace encoding").
//
//   codec    INTEGER (schema v4): which encoding `data` has:
//            0 (kRawFloat64): channels.size() * samples IEEE-754 binary64 values, little-endian, channel-major
//              (all samples of channel 0, then all of channel 1, ...), exactly TraceChunk::data; no header. Every
//              chunk written before schema v4 is stored this way, and stays readable.
//            1 (kShuffledZstd): lossless compression (below). What the store writes since schema v4.
//   channels TEXT: the channel names joined by '\n' (names are non-empty, unique, without '\n').
//   samples, t0, period: their own columns.
//
// Codec 1 layout: one byte per channel naming the transform applied to it (Transform), then one zstd frame
// (with its content size) of the transformed values, byte-shuffled: per channel, its n 64-bit words as 8 planes
// of n bytes (plane b holds byte b, least significant first, of every word). The transforms work on the bit
// patterns of the doubles (uint64), so every bit survives: NaN payloads and signs, signed zeros, infinities and
// subnormals come back as they went in. They turn a sampled physical signal into words with many zero high
// bytes (a slowly varying value differs little from its predecessor; time steps are nearly constant; a gate or
// a counter is constant between edges), which the shuffle gathers into long runs that zstd removes.
//
// Internal to db/.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"
#include "db/records.h"

struct ZSTD_CCtx_s;
struct ZSTD_DCtx_s;

namespace vb::db::trace {

inline constexpr bool kNativeIsLittleEndian = std::endian::native == std::endian::little;
static_assert(kNativeIsLittleEndian || std::endian::native == std::endian::big, "mixed-endian hosts unsupported");
static_assert(sizeof(double) == 8, "binary64 doubles required");

enum class Codec : std::int32_t { kRawFloat64 = 0, kShuffledZstd = 1 };

// Per-channel transforms of codec 1 on the words w[k] (bit patterns); w[-1] = 0, d[-1] = 0.
enum class Transform : std::uint8_t {
  kNone = 0,          // w[k]
  kXor = 1,           // w[k] ^ w[k-1]
  kDelta = 2,         // zigzag(w[k] - w[k-1])  (wrapping int64 difference; zigzag puts small negatives near 0)
  kDeltaOfDelta = 3,  // zigzag(d[k] - d[k-1]), d[k] = w[k] - w[k-1]  (e.g. time, counters at a steady rate)
};

// Checks a chunk on its own (shape, names, times); messages start with "trace chunk <index>: ".
Status ValidateChunk(const TraceChunk& chunk);

std::string JoinChannels(const std::vector<std::string>& channels);
std::vector<std::string> SplitChannels(std::string_view joined);

// Codec 0 ------------------------------------------------------------------------------------------------------
// The BLOB bytes for `values` (little-endian float64).
std::string EncodeValues(const std::vector<double>& values);
// DataLoss unless a stored BLOB of `size` bytes holds exactly `expected_values` float64s. `what` names the chunk.
Status CheckSize(std::size_t size, std::size_t expected_values, std::string_view what);
// Turns values read verbatim from a BLOB into native doubles (nothing to do on little-endian hosts).
void FromLittleEndian(std::vector<double>* values);

// Codec 1 ------------------------------------------------------------------------------------------------------
// Reusable state (zstd contexts, scratch buffers) for one thread: a Store owns one. Not thread-safe.
class Codec1 {
 public:
  // zstd level: 1 by default (docs/store.md, "Compression": higher levels gained little on traces, cost ingest).
  explicit Codec1(int zstd_level = 1);
  ~Codec1();
  Codec1(const Codec1&) = delete;
  Codec1& operator=(const Codec1&) = delete;

  // Encodes `samples` values of each of `channels` channels (channel-major, as TraceChunk::data) into *out.
  Status Encode(const double* data, std::size_t channels, std::size_t samples, std::string* out);
  // Decodes a codec-1 BLOB into exactly channels * samples values; DataLoss (prefixed with `what`) if the
  // BLOB is not a well-formed encoding of that shape.
  Status Decode(const void* blob, std::size_t size, std::size_t channels, std::size_t samples, double* out,
                std::string_view what);
  // The transform Encode chose for each channel of the last chunk it encoded (for tests and perf output).
  const std::vector<Transform>& last_transforms() const { return transforms_; }

 private:
  int level_;
  ZSTD_CCtx_s* cctx_ = nullptr;
  ZSTD_DCtx_s* dctx_ = nullptr;
  std::vector<std::uint8_t> shuffled_;
  std::vector<std::uint64_t> words_;
  std::vector<Transform> transforms_;
};

}  // namespace vb::db::trace
